//! The `%`-prefixed text header of Prophesee `.raw` files: event format version and sensor size.
//!
//! The header is the run of lines starting with `%` at the start of the file; the binary data
//! starts at the first byte of the first line that does not. Recognised lines (case-insensitive
//! keys): `% evt 3.0`, `% format EVT3;height=720;width=1280`, `% geometry 1280x720`,
//! `% Width 640` / `% Height 480`.

use std::fs::File;
use std::io::{BufRead, BufReader, Read};
use std::path::Path;

use crate::DecodeError;

/// Longest header line accepted, bytes. Real headers have lines of well under 200 bytes; the
/// limit only keeps a corrupt file from making us buffer gigabytes.
const MAX_HEADER_LINE: u64 = 64 * 1024;

/// The event encoding named in a header.
#[derive(Debug, Clone, PartialEq, Eq)]
pub(crate) enum EvtVersion {
    /// EVT 2.0.
    Evt2,
    /// EVT 3.0.
    Evt3,
    /// Another encoding (EVT 2.1, DAT, ...), as written in the header.
    Other(String),
}

/// What the header says.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub(crate) struct PropheseeHeader {
    /// Event encoding, if named.
    pub version: Option<EvtVersion>,
    /// Sensor (width, height) in pixels, if given.
    pub geometry: Option<(u16, u16)>,
    /// Header length, bytes (offset of the first data byte).
    pub length: u64,
}

impl PropheseeHeader {
    fn parse_line(&mut self, line: &[u8]) {
        let text = String::from_utf8_lossy(line);
        let text = text.trim_start_matches('%');
        let words: Vec<&str> = text
            .split([' ', ';', '\t', '\r', '\n'])
            .map(str::trim)
            .filter(|w| !w.is_empty())
            .collect();
        let [key, value, rest @ ..] = words.as_slice() else {
            return;
        };
        match key.to_ascii_lowercase().as_str() {
            "evt" => self.version = Some(version_from_number(value)),
            "format" => {
                self.version = Some(version_from_format(value));
                let mut width = None;
                let mut height = None;
                for item in rest {
                    if let Some((k, v)) = item.split_once('=') {
                        match k.trim().to_ascii_lowercase().as_str() {
                            "width" => width = v.trim().parse::<u16>().ok(),
                            "height" => height = v.trim().parse::<u16>().ok(),
                            _ => {}
                        }
                    }
                }
                if let (Some(w), Some(h)) = (width, height) {
                    self.geometry = Some((w, h));
                }
            }
            "geometry" => {
                if let Some((w, h)) = value.split_once(['x', 'X'])
                    && let (Ok(w), Ok(h)) = (w.trim().parse::<u16>(), h.trim().parse::<u16>())
                {
                    self.geometry = Some((w, h));
                }
            }
            "width" => {
                if let Ok(w) = value.parse::<u16>() {
                    self.geometry = Some((w, self.geometry.map_or(0, |g| g.1)));
                }
            }
            "height" => {
                if let Ok(h) = value.parse::<u16>() {
                    self.geometry = Some((self.geometry.map_or(0, |g| g.0), h));
                }
            }
            _ => {}
        }
    }
}

fn version_from_number(value: &str) -> EvtVersion {
    match value {
        "2" | "2.0" => EvtVersion::Evt2,
        "3" | "3.0" => EvtVersion::Evt3,
        other => EvtVersion::Other(other.to_string()),
    }
}

fn version_from_format(value: &str) -> EvtVersion {
    match value.to_ascii_uppercase().as_str() {
        "EVT2" | "EVT2.0" | "EVT20" => EvtVersion::Evt2,
        "EVT3" | "EVT3.0" | "EVT30" => EvtVersion::Evt3,
        _ => EvtVersion::Other(value.to_string()),
    }
}

/// Reads the header of the `.raw` file at `path`.
pub(crate) fn read_header(path: &Path) -> Result<PropheseeHeader, DecodeError> {
    let mut header = PropheseeHeader::default();
    let io_error = |offset, source| DecodeError::Io {
        path: path.to_path_buf(),
        offset,
        source,
    };
    let file = File::open(path).map_err(|e| io_error(0, e))?;
    let mut reader = BufReader::new(file);
    let mut line = Vec::new();
    loop {
        let first = reader.fill_buf().map_err(|e| io_error(header.length, e))?;
        if first.first() != Some(&b'%') {
            break;
        }
        line.clear();
        let n = (&mut reader)
            .take(MAX_HEADER_LINE)
            .read_until(b'\n', &mut line)
            .map_err(|e| io_error(header.length, e))?;
        if n as u64 == MAX_HEADER_LINE && line.last() != Some(&b'\n') {
            return Err(DecodeError::Corrupt {
                path: path.to_path_buf(),
                offset: header.length,
                what: format!("header line longer than {MAX_HEADER_LINE} bytes"),
            });
        }
        header.parse_line(&line);
        header.length += n as u64;
    }
    if let Some((w, h)) = header.geometry
        && (w == 0 || h == 0)
    {
        return Err(DecodeError::Corrupt {
            path: path.to_path_buf(),
            offset: 0,
            what: format!("header gives an empty sensor size {w}x{h}"),
        });
    }
    Ok(header)
}

/// Opens a `.raw` file: reads its header, checks that it names `expected` (or nothing), and
/// picks the sensor size: the header's, else `options.geometry`, else `fallback`. Returns the
/// header and the size.
pub(crate) fn open_raw(
    path: &Path,
    expected: EvtVersion,
    options: &crate::OpenOptions,
    fallback: Option<(u16, u16)>,
) -> Result<(PropheseeHeader, (u16, u16)), DecodeError> {
    let header = read_header(path)?;
    if let Some(version) = &header.version
        && *version != expected
    {
        return Err(DecodeError::Unsupported {
            path: path.to_path_buf(),
            what: format!("the header names event format {version:?}, not {expected:?}"),
        });
    }
    let geometry = match header.geometry.or(options.geometry).or(fallback) {
        Some((w, h)) if w > 0 && h > 0 => (w, h),
        Some((w, h)) => {
            return Err(DecodeError::Unsupported {
                path: path.to_path_buf(),
                what: format!("empty sensor size {w}x{h}"),
            });
        }
        None => {
            return Err(DecodeError::Unsupported {
                path: path.to_path_buf(),
                what: "the header gives no sensor size (no `% geometry` or `% format ...;width=;height=` \
                       line): give it as width and height in the source node's camera_file (OpenOptions::geometry in code)"
                    .into(),
            });
        }
    };
    Ok((header, geometry))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn parse(lines: &[&str]) -> PropheseeHeader {
        let mut header = PropheseeHeader::default();
        for line in lines {
            header.parse_line(line.as_bytes());
        }
        header
    }

    #[test]
    fn format_line_with_size() {
        let h = parse(&["% format EVT3;height=720;width=1280\n"]);
        assert_eq!(h.version, Some(EvtVersion::Evt3));
        assert_eq!(h.geometry, Some((1280, 720)));
    }

    #[test]
    fn evt_and_geometry_lines() {
        let h = parse(&["% evt 2.0\r\n", "% geometry 640x480\n"]);
        assert_eq!(h.version, Some(EvtVersion::Evt2));
        assert_eq!(h.geometry, Some((640, 480)));
        let h = parse(&["% evt 2.1\n"]);
        assert_eq!(h.version, Some(EvtVersion::Other("2.1".into())));
        let h = parse(&["% Date 2020-09-25 07:48:31\n"]);
        assert_eq!(h, PropheseeHeader::default());
    }
}
