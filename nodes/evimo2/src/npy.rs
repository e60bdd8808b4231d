//! The `.npy` format (numpy's `NEP 1` file format), versions 1.0, 2.0 and 3.0, written by hand.
//!
//! Layout: magic `\x93NUMPY`, major and minor version bytes, the header length (u16 little-endian
//! for 1.0, u32 for 2.0/3.0), an ASCII (3.0: UTF-8) Python dict literal with `descr`,
//! `fortran_order` and `shape`, padded with spaces and a newline, then the raw data.

use std::io::Read;

use crate::error::{Evimo2Error, Result};
use crate::pylit::{self, PyValue};

/// Element type of an array (the `descr` without byte order).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum DType {
    /// `?` numpy bool, 1 byte.
    Bool,
    /// `u1`.
    U1,
    /// `u2`.
    U2,
    /// `u4`.
    U4,
    /// `u8`.
    U8,
    /// `i1`.
    I1,
    /// `i2`.
    I2,
    /// `i4`.
    I4,
    /// `i8`.
    I8,
    /// `f4`.
    F4,
    /// `f8`.
    F8,
    /// `U<n>`: fixed-length unicode string of `n` UTF-32 code units.
    Unicode(usize),
    /// `O`: Python objects; the data is a pickle of the whole array.
    Object,
}

impl DType {
    /// Bytes per element (0 for object arrays, whose data is a pickle).
    pub fn item_size(self) -> usize {
        match self {
            DType::Bool | DType::U1 | DType::I1 => 1,
            DType::U2 | DType::I2 => 2,
            DType::U4 | DType::I4 | DType::F4 => 4,
            DType::U8 | DType::I8 | DType::F8 => 8,
            DType::Unicode(n) => 4 * n,
            DType::Object => 0,
        }
    }

    /// True for integer and bool types.
    pub fn is_integer(self) -> bool {
        matches!(
            self,
            DType::Bool
                | DType::U1
                | DType::U2
                | DType::U4
                | DType::U8
                | DType::I1
                | DType::I2
                | DType::I4
                | DType::I8
        )
    }
}

/// A parsed `.npy` header.
#[derive(Debug, Clone, PartialEq)]
pub struct NpyHeader {
    /// The `descr` string as written, e.g. `<f8`.
    pub descr: String,
    /// Element type.
    pub dtype: DType,
    /// True when multi-byte elements are big-endian (`>`).
    pub big_endian: bool,
    /// True for Fortran (column-major) order.
    pub fortran_order: bool,
    /// Array shape; empty for a 0-d array.
    pub shape: Vec<usize>,
    /// Byte offset of the first data byte from the start of the file.
    pub data_offset: u64,
}

impl NpyHeader {
    /// Number of elements (product of the shape), or `None` on overflow.
    pub fn count(&self) -> Option<u64> {
        self.shape
            .iter()
            .try_fold(1u64, |acc, &d| acc.checked_mul(d as u64))
    }

    /// Number of data bytes, or `None` on overflow or for object arrays.
    pub fn data_len(&self) -> Option<u64> {
        if self.dtype == DType::Object {
            return None;
        }
        self.count()?.checked_mul(self.dtype.item_size() as u64)
    }
}

const MAGIC: &[u8; 6] = b"\x93NUMPY";

/// Longest header accepted, bytes. numpy itself refuses headers over 10 000 bytes by default
/// (`max_header_size`); 1 MiB leaves room for odd writers while refusing garbage lengths.
const MAX_HEADER_LEN: usize = 1 << 20;

/// Reads and parses the header from the start of `r`; `file` names the source in errors.
pub fn read_header<R: Read>(r: &mut R, file: &str) -> Result<NpyHeader> {
    let mut pre = [0u8; 8];
    read_exact_or_truncated(r, &mut pre, 0, file)?;
    if &pre[..6] != MAGIC {
        return Err(Evimo2Error::format(
            file,
            0,
            "not a .npy file (magic \\x93NUMPY missing)",
        ));
    }
    let (major, minor) = (pre[6], pre[7]);
    let (len_size, utf8) = match major {
        1 => (2usize, false),
        2 => (4, false),
        3 => (4, true),
        _ => {
            return Err(Evimo2Error::format(
                file,
                6,
                format!("unsupported .npy version {major}.{minor} (1.0, 2.0 and 3.0 are)"),
            ));
        }
    };
    let mut len_bytes = [0u8; 4];
    read_exact_or_truncated(r, &mut len_bytes[..len_size], 8, file)?;
    let header_len = u32::from_le_bytes(len_bytes) as usize;
    let header_start = 8 + len_size;
    if header_len > MAX_HEADER_LEN {
        return Err(Evimo2Error::format(
            file,
            8,
            format!("header length {header_len} is implausible"),
        ));
    }
    let mut header = vec![0u8; header_len];
    read_exact_or_truncated(r, &mut header, header_start as u64, file)?;
    let text = if utf8 {
        String::from_utf8(header).map_err(|e| {
            Evimo2Error::format(
                file,
                (header_start + e.utf8_error().valid_up_to()) as u64,
                "header is not UTF-8",
            )
        })?
    } else {
        match header.iter().position(|b| !b.is_ascii()) {
            Some(i) => {
                return Err(Evimo2Error::format(
                    file,
                    (header_start + i) as u64,
                    "header is not ASCII",
                ));
            }
            None => String::from_utf8_lossy(&header).into_owned(),
        }
    };
    parse_header_text(&text, header_start, header_len, file)
}

fn parse_header_text(text: &str, header_start: usize, header_len: usize, file: &str) -> Result<NpyHeader> {
    let value = pylit::parse(text).map_err(|e| {
        // Header text is ASCII (or UTF-8 in 3.0); convert the char offset to a byte offset.
        let byte = text.char_indices().nth(e.offset).map_or(text.len(), |(b, _)| b);
        Evimo2Error::format(
            file,
            (header_start + byte) as u64,
            format!("malformed header: {}", e.message),
        )
    })?;
    let at = header_start as u64;
    let descr = match value.get("descr") {
        Some(PyValue::Str(s)) => s.clone(),
        Some(other) => {
            return Err(Evimo2Error::format(
                file,
                at,
                format!(
                    "unsupported descr of type {} (structured dtypes are not supported)",
                    other.type_name()
                ),
            ));
        }
        None => return Err(Evimo2Error::format(file, at, "header has no 'descr'")),
    };
    let fortran_order = match value.get("fortran_order") {
        Some(PyValue::Bool(b)) => *b,
        _ => {
            return Err(Evimo2Error::format(
                file,
                at,
                "header has no boolean 'fortran_order'",
            ));
        }
    };
    let shape = match value.get("shape") {
        Some(PyValue::Tuple(dims)) => dims
            .iter()
            .map(|d| match d {
                PyValue::Int(n) if *n >= 0 && *n <= usize::MAX as i128 => Ok(*n as usize),
                _ => Err(Evimo2Error::format(
                    file,
                    at,
                    format!("bad dimension {d} in 'shape'"),
                )),
            })
            .collect::<Result<Vec<_>>>()?,
        _ => return Err(Evimo2Error::format(file, at, "header has no tuple 'shape'")),
    };
    let (dtype, big_endian) = parse_descr(&descr)
        .ok_or_else(|| Evimo2Error::format(file, at, format!("unsupported dtype '{descr}'")))?;
    Ok(NpyHeader {
        descr,
        dtype,
        big_endian,
        fortran_order,
        shape,
        data_offset: (header_start + header_len) as u64,
    })
}

/// Splits a `descr` such as `<f8`, `|u1`, `<U12` or `|O` into type and big-endianness.
pub fn parse_descr(descr: &str) -> Option<(DType, bool)> {
    let mut chars = descr.chars();
    let first = chars.clone().next()?;
    let (big, rest) = match first {
        '<' | '|' | '=' => {
            chars.next();
            (false, chars.as_str())
        }
        '>' => {
            chars.next();
            (true, chars.as_str())
        }
        _ => (false, descr),
    };
    let dtype = match rest {
        "?" | "b1" => DType::Bool,
        "u1" | "B" => DType::U1,
        "u2" => DType::U2,
        "u4" => DType::U4,
        "u8" => DType::U8,
        "i1" | "b" => DType::I1,
        "i2" => DType::I2,
        "i4" => DType::I4,
        "i8" => DType::I8,
        "f4" => DType::F4,
        "f8" => DType::F8,
        "O" | "O8" => DType::Object,
        _ => {
            let n = rest.strip_prefix('U')?.parse::<usize>().ok()?;
            DType::Unicode(n)
        }
    };
    Some((dtype, big))
}

fn read_exact_or_truncated<R: Read>(r: &mut R, buf: &mut [u8], offset: u64, file: &str) -> Result<()> {
    let mut filled = 0;
    while filled < buf.len() {
        match r.read(&mut buf[filled..]) {
            Ok(0) => {
                return Err(Evimo2Error::format(
                    file,
                    offset + filled as u64,
                    "file ends inside the .npy header (truncated)",
                ));
            }
            Ok(n) => filled += n,
            Err(e) if e.kind() == std::io::ErrorKind::Interrupted => {}
            Err(e) => return Err(Evimo2Error::io(file, e)),
        }
    }
    Ok(())
}

/// Builds a version 1.0 header (version 2.0 if it would not fit), padded so the data starts on a
/// 64-byte boundary as numpy ≥ 1.16 writes it.
pub fn encode_header(descr: &str, fortran_order: bool, shape: &[usize]) -> Vec<u8> {
    encode_header_at_least(descr, fortran_order, shape, 0)
}

/// [`encode_header`] padded with spaces to at least `min_len` bytes (rounded up to 64): a file
/// written before its row count is known reserves the header of the largest count and rewrites
/// it in place at the end.
pub fn encode_header_at_least(descr: &str, fortran_order: bool, shape: &[usize], min_len: usize) -> Vec<u8> {
    let shape_text = match shape.len() {
        0 => "()".to_string(),
        1 => format!("({},)", shape[0]),
        _ => format!(
            "({})",
            shape.iter().map(|d| d.to_string()).collect::<Vec<_>>().join(", ")
        ),
    };
    let fortran = if fortran_order { "True" } else { "False" };
    let dict = format!("{{'descr': '{descr}', 'fortran_order': {fortran}, 'shape': {shape_text}, }}");
    // Version 1.0 (u16 header length) unless the header is too long for it, then 2.0 (u32).
    let v1_total = (8 + 2 + dict.len() + 1).div_ceil(64) * 64;
    let (major, len_size) = if v1_total - 10 <= u16::MAX as usize {
        (1u8, 2usize)
    } else {
        (2, 4)
    };
    let total = (8 + len_size + dict.len() + 1).max(min_len).div_ceil(64) * 64;
    let header_len = total - 8 - len_size;
    let mut out = Vec::with_capacity(total);
    out.extend_from_slice(MAGIC);
    out.extend_from_slice(&[major, 0]);
    if len_size == 2 {
        out.extend_from_slice(&(header_len as u16).to_le_bytes());
    } else {
        out.extend_from_slice(&(header_len as u32).to_le_bytes());
    }
    out.extend_from_slice(dict.as_bytes());
    out.resize(total - 1, b' ');
    out.push(b'\n');
    out
}

/// A whole array in memory (used for npz members and small files).
#[derive(Debug, Clone, PartialEq)]
pub struct NpyArray {
    /// The header (its `data_offset` is relative to the start of `bytes` given to [`parse_bytes`]).
    pub header: NpyHeader,
    /// Raw data bytes (the pickle for object arrays).
    pub data: Vec<u8>,
}

/// Parses a complete `.npy` image; checks that the data length matches the header.
pub fn parse_bytes(bytes: &[u8], file: &str) -> Result<NpyArray> {
    let mut cursor = bytes;
    let header = read_header(&mut cursor, file)?;
    let start = header.data_offset as usize;
    let data = &bytes[start.min(bytes.len())..];
    if let Some(expected) = header.data_len() {
        if (data.len() as u64) < expected {
            return Err(Evimo2Error::format(
                file,
                bytes.len() as u64,
                format!(
                    "truncated: {} data bytes for shape {:?} of {} need {expected}, only {} present",
                    header.descr,
                    header.shape,
                    header.descr,
                    data.len()
                ),
            ));
        }
        let data = data[..expected as usize].to_vec();
        return Ok(NpyArray { header, data });
    }
    if header.dtype == DType::Object {
        return Ok(NpyArray {
            header,
            data: data.to_vec(),
        });
    }
    Err(Evimo2Error::format(
        file,
        0,
        format!("shape {:?} is too large", header.shape),
    ))
}

/// Serialises a numeric/unicode array: header plus `data` (already in the byte order of `descr`).
pub fn encode_array(descr: &str, shape: &[usize], data: &[u8]) -> Vec<u8> {
    let mut out = encode_header(descr, false, shape);
    out.extend_from_slice(data);
    out
}

/// Appends `bytes` decoded as `dtype` numbers converted to f64.
pub fn decode_f64_into(dtype: DType, big: bool, bytes: &[u8], out: &mut Vec<f64>) -> bool {
    macro_rules! conv {
        ($t:ty, $n:expr) => {{
            out.extend(bytes.chunks_exact($n).map(|c| {
                let a: [u8; $n] = c.try_into().unwrap_or([0; $n]);
                (if big {
                    <$t>::from_be_bytes(a)
                } else {
                    <$t>::from_le_bytes(a)
                }) as f64
            }));
            true
        }};
    }
    match dtype {
        DType::F8 => conv!(f64, 8),
        DType::F4 => conv!(f32, 4),
        DType::Bool | DType::U1 => conv!(u8, 1),
        DType::I1 => conv!(i8, 1),
        DType::U2 => conv!(u16, 2),
        DType::I2 => conv!(i16, 2),
        DType::U4 => conv!(u32, 4),
        DType::I4 => conv!(i32, 4),
        DType::U8 => conv!(u64, 8),
        DType::I8 => conv!(i64, 8),
        DType::Unicode(_) | DType::Object => false,
    }
}

/// Appends `bytes` decoded as integers (bool/int types only) widened to i128.
/// Returns false for non-integer dtypes.
pub fn decode_int_into(dtype: DType, big: bool, bytes: &[u8], out: &mut Vec<i128>) -> bool {
    macro_rules! conv {
        ($t:ty, $n:expr) => {{
            out.extend(bytes.chunks_exact($n).map(|c| {
                let a: [u8; $n] = c.try_into().unwrap_or([0; $n]);
                i128::from(if big {
                    <$t>::from_be_bytes(a)
                } else {
                    <$t>::from_le_bytes(a)
                })
            }));
            true
        }};
    }
    match dtype {
        DType::Bool | DType::U1 => conv!(u8, 1),
        DType::I1 => conv!(i8, 1),
        DType::U2 => conv!(u16, 2),
        DType::I2 => conv!(i16, 2),
        DType::U4 => conv!(u32, 4),
        DType::I4 => conv!(i32, 4),
        DType::U8 => conv!(u64, 8),
        DType::I8 => conv!(i64, 8),
        _ => false,
    }
}

/// Decodes `bytes` as u16 values. Fast path for `<u2`; other integer types are range-checked.
/// `Err(Some(i))` names the first out-of-range element, `Err(None)` means a non-integer dtype.
pub fn decode_u16(dtype: DType, big: bool, bytes: &[u8]) -> std::result::Result<Vec<u16>, Option<usize>> {
    if dtype == DType::U2 {
        return Ok(bytes
            .chunks_exact(2)
            .map(|c| {
                let a = [c[0], c[1]];
                if big {
                    u16::from_be_bytes(a)
                } else {
                    u16::from_le_bytes(a)
                }
            })
            .collect());
    }
    decode_narrow(dtype, big, bytes)
}

/// Decodes `bytes` as event polarities, 1 = ON (value > 0) and 0 = OFF (value <= 0), from a
/// bool, integer or float dtype: EVIMO2 stores 0 / 1 as uint8, other tools write -1 / +1 as
/// signed integers or floats. `Err(Some(i))` names the first NaN, `Err(None)` means a dtype that
/// is not numeric.
pub fn decode_polarity(dtype: DType, big: bool, bytes: &[u8]) -> std::result::Result<Vec<u8>, Option<usize>> {
    if matches!(dtype, DType::U1 | DType::Bool) {
        return Ok(bytes.iter().map(|&b| u8::from(b != 0)).collect());
    }
    let mut wide = Vec::new();
    if decode_int_into(dtype, big, bytes, &mut wide) {
        return Ok(wide.into_iter().map(|v| u8::from(v > 0)).collect());
    }
    // Only float dtypes are left: integer and bool ones returned above.
    let mut floats = Vec::new();
    if !decode_f64_into(dtype, big, bytes, &mut floats) {
        return Err(None);
    }
    floats
        .into_iter()
        .enumerate()
        .map(|(i, v)| {
            if v.is_nan() {
                Err(Some(i))
            } else {
                Ok(u8::from(v > 0.0))
            }
        })
        .collect()
}

fn decode_narrow<T: TryFrom<i128>>(
    dtype: DType,
    big: bool,
    bytes: &[u8],
) -> std::result::Result<Vec<T>, Option<usize>> {
    let mut wide = Vec::new();
    if !decode_int_into(dtype, big, bytes, &mut wide) {
        return Err(None);
    }
    wide.into_iter()
        .enumerate()
        .map(|(i, v)| T::try_from(v).map_err(|_| Some(i)))
        .collect()
}

/// Decodes a 0-d or 1-element `<U`/`>U` array into a Rust string (trailing NULs removed).
pub fn decode_unicode(dtype: DType, big: bool, bytes: &[u8]) -> std::result::Result<String, usize> {
    let DType::Unicode(_) = dtype else { return Err(0) };
    let mut s = String::with_capacity(bytes.len() / 4);
    for (i, c) in bytes.chunks_exact(4).enumerate() {
        let a = [c[0], c[1], c[2], c[3]];
        let code = if big {
            u32::from_be_bytes(a)
        } else {
            u32::from_le_bytes(a)
        };
        s.push(char::from_u32(code).ok_or(i * 4)?);
    }
    while s.ends_with('\0') {
        s.pop();
    }
    Ok(s)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn header_round_trip_and_alignment() {
        for shape in [vec![], vec![5], vec![480, 640], vec![3, 2]] {
            let h = encode_header("<u2", false, &shape);
            assert_eq!(h.len() % 64, 0);
            let parsed = read_header(&mut &h[..], "x.npy").unwrap();
            assert_eq!(parsed.shape, shape);
            assert_eq!(parsed.dtype, DType::U2);
            assert_eq!(parsed.data_offset as usize, h.len());
        }
    }

    #[test]
    fn long_header_switches_to_version_2() {
        let shape = vec![1usize; 25_000];
        let h = encode_header("<u1", false, &shape);
        assert_eq!((h[6], h.len() % 64), (2, 0));
        let parsed = read_header(&mut &h[..], "long.npy").unwrap();
        assert_eq!(parsed.shape.len(), 25_000);
        assert_eq!(parsed.data_offset as usize, h.len());
    }

    #[test]
    fn version_2_and_3_headers() {
        for major in [2u8, 3] {
            let dict = b"{'descr': '>f8', 'fortran_order': False, 'shape': (2,), }\n";
            let mut bytes = MAGIC.to_vec();
            bytes.extend_from_slice(&[major, 0]);
            bytes.extend_from_slice(&(dict.len() as u32).to_le_bytes());
            bytes.extend_from_slice(dict);
            bytes.extend_from_slice(&1.5f64.to_be_bytes());
            bytes.extend_from_slice(&(-2.0f64).to_be_bytes());
            let a = parse_bytes(&bytes, "v.npy").unwrap();
            assert!(a.header.big_endian);
            let mut out = Vec::new();
            assert!(decode_f64_into(a.header.dtype, true, &a.data, &mut out));
            assert_eq!(out, vec![1.5, -2.0]);
        }
    }

    #[test]
    fn descr_variants() {
        assert_eq!(parse_descr("<f8"), Some((DType::F8, false)));
        assert_eq!(parse_descr("|u1"), Some((DType::U1, false)));
        assert_eq!(parse_descr("<U37"), Some((DType::Unicode(37), false)));
        assert_eq!(parse_descr("|O"), Some((DType::Object, false)));
        assert_eq!(parse_descr(">i8"), Some((DType::I8, true)));
        assert_eq!(parse_descr("<c16"), None);
    }

    #[test]
    fn errors_name_file_and_offset() {
        let h = encode_header("<f8", false, &[4]);
        let mut bytes = h.clone();
        bytes.extend_from_slice(&[0u8; 20]);
        let e = parse_bytes(&bytes, "t.npy").unwrap_err().to_string();
        assert!(e.contains("t.npy") && e.contains("truncated"), "{e}");
        let e = parse_bytes(&h[..30], "short.npy").unwrap_err().to_string();
        assert!(e.contains("short.npy: byte 30"), "{e}");
        let e = parse_bytes(b"PK\x03\x04 not npy", "z.npy")
            .unwrap_err()
            .to_string();
        assert!(e.contains("z.npy: byte 0"), "{e}");
        let mut bad = h.clone();
        bad[10] = b'[';
        let e = parse_bytes(&bad, "b.npy").unwrap_err().to_string();
        assert!(e.contains("b.npy: byte") && e.contains("malformed header"), "{e}");
    }

    #[test]
    fn narrow_decoding_checks_range() {
        let bytes: Vec<u8> = [5i64, 70000].iter().flat_map(|v| v.to_le_bytes()).collect();
        assert_eq!(decode_u16(DType::I8, false, &bytes), Err(Some(1)));
        assert_eq!(decode_u16(DType::I8, false, &bytes[..8]), Ok(vec![5]));
    }

    #[test]
    fn polarities_of_any_numeric_type_become_on_off() {
        assert_eq!(decode_polarity(DType::U1, false, &[0, 1, 2]), Ok(vec![0, 1, 1]));
        let signed: Vec<u8> = [-1i8, 1, 0].iter().map(|v| *v as u8).collect();
        assert_eq!(decode_polarity(DType::I1, false, &signed), Ok(vec![0, 1, 0]));
        let big: Vec<u8> = [-1i32, 1].iter().flat_map(|v| v.to_be_bytes()).collect();
        assert_eq!(decode_polarity(DType::I4, true, &big), Ok(vec![0, 1]));
        let floats: Vec<u8> = [-1.0f64, 1.0, f64::NAN]
            .iter()
            .flat_map(|v| v.to_le_bytes())
            .collect();
        assert_eq!(decode_polarity(DType::F8, false, &floats[..16]), Ok(vec![0, 1]));
        assert_eq!(decode_polarity(DType::F8, false, &floats), Err(Some(2)));
        assert_eq!(decode_polarity(DType::Unicode(1), false, &[0; 4]), Err(None));
    }
}
