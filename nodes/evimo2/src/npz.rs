//! `.npz` archives: a zip file of `.npy` members (`np.savez` stores them, `np.savez_compressed`
//! deflates them). Members are read one at a time, on demand.

use std::fs::File;
use std::io::{BufReader, BufWriter, Read, Write};
use std::path::Path;

use zip::write::SimpleFileOptions;
use zip::{CompressionMethod, ZipArchive, ZipWriter};

use crate::error::{Evimo2Error, Result};
use crate::npy::{self, NpyArray};

/// Largest member accepted, bytes (uncompressed). A 2080 x 1552 uint16 mask, EVIMO2's largest,
/// is 6.5 MB; 1 GiB refuses zip bombs and corrupt size fields without limiting real data.
const MAX_MEMBER_BYTES: u64 = 1 << 30;

/// An open `.npz` archive.
pub struct NpzReader {
    file: String,
    archive: ZipArchive<BufReader<File>>,
}

impl std::fmt::Debug for NpzReader {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("NpzReader")
            .field("file", &self.file)
            .field("members", &self.archive.len())
            .finish()
    }
}

impl NpzReader {
    /// Opens the archive and reads its central directory.
    pub fn open(path: &Path) -> Result<Self> {
        let file = path.display().to_string();
        let f = File::open(path).map_err(|e| Evimo2Error::io(&file, e))?;
        let archive = ZipArchive::new(BufReader::new(f)).map_err(|source| Evimo2Error::Zip {
            file: file.clone(),
            source,
        })?;
        Ok(Self { file, archive })
    }

    /// The archive's path, as used in error messages.
    pub fn file(&self) -> &str {
        &self.file
    }

    /// Names of all members (e.g. `mask_0000000012.npy`), in archive order.
    pub fn member_names(&self) -> Vec<String> {
        self.archive.file_names().map(str::to_string).collect()
    }

    /// True when the archive has a member of that name.
    pub fn contains(&self, member: &str) -> bool {
        self.archive.index_for_name(member).is_some()
    }

    /// Reads and parses one member by its name (`key.npy`).
    pub fn read_member(&mut self, member: &str) -> Result<NpyArray> {
        let label = format!("{}[{member}]", self.file);
        let Some(index) = self.archive.index_for_name(member) else {
            let mut names = self.member_names();
            let more = names.len() > 20;
            names.truncate(20);
            let mut available = names.join(", ");
            if more {
                available.push_str(", ...");
            }
            return Err(Evimo2Error::MissingMember {
                file: self.file.clone(),
                member: member.into(),
                available,
            });
        };
        let mut entry = self.archive.by_index(index).map_err(|source| Evimo2Error::Zip {
            file: label.clone(),
            source,
        })?;
        let size = entry.size();
        if size > MAX_MEMBER_BYTES {
            return Err(Evimo2Error::invalid(
                &label,
                format!("member of {size} bytes exceeds the limit"),
            ));
        }
        let mut bytes = Vec::with_capacity(size as usize);
        entry
            .read_to_end(&mut bytes)
            .map_err(|e| Evimo2Error::io(&label, e))?;
        npy::parse_bytes(&bytes, &label)
    }

    /// Reads member `key.npy`.
    pub fn read_key(&mut self, key: &str) -> Result<NpyArray> {
        self.read_member(&format!("{key}.npy"))
    }
}

/// Writes an `.npz` archive member by member.
pub struct NpzWriter {
    file: String,
    zip: ZipWriter<BufWriter<File>>,
    options: SimpleFileOptions,
}

impl NpzWriter {
    /// Creates (truncates) the archive. `compressed` = deflate as `np.savez_compressed`,
    /// otherwise stored as `np.savez`.
    pub fn create(path: &Path, compressed: bool) -> Result<Self> {
        let file = path.display().to_string();
        let f = File::create(path).map_err(|e| Evimo2Error::io(&file, e))?;
        let method = if compressed {
            CompressionMethod::Deflated
        } else {
            CompressionMethod::Stored
        };
        let options = SimpleFileOptions::default()
            .compression_method(method)
            .large_file(false);
        Ok(Self {
            file,
            zip: ZipWriter::new(BufWriter::new(f)),
            options,
        })
    }

    /// Adds member `key.npy` holding the complete `.npy` image `npy_bytes`.
    pub fn add(&mut self, key: &str, npy_bytes: &[u8]) -> Result<()> {
        let label = format!("{}[{key}.npy]", self.file);
        let options = self.options.large_file(npy_bytes.len() as u64 >= u32::MAX as u64);
        self.zip
            .start_file(format!("{key}.npy"), options)
            .map_err(|source| Evimo2Error::Zip {
                file: label.clone(),
                source,
            })?;
        self.zip
            .write_all(npy_bytes)
            .map_err(|e| Evimo2Error::io(&label, e))
    }

    /// Writes the central directory and flushes the file.
    pub fn finish(self) -> Result<()> {
        let file = self.file;
        let mut w = self.zip.finish().map_err(|source| Evimo2Error::Zip {
            file: file.clone(),
            source,
        })?;
        w.flush().map_err(|e| Evimo2Error::io(&file, e))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn write_then_read_members_both_compressions() {
        let dir = tempfile::tempdir().unwrap();
        for compressed in [false, true] {
            let path = dir.path().join(format!("a{compressed}.npz"));
            let mut w = NpzWriter::create(&path, compressed).unwrap();
            let data: Vec<u8> = (0u16..600).flat_map(|v| v.to_le_bytes()).collect();
            w.add("mask_0000000000", &npy::encode_array("<u2", &[20, 30], &data))
                .unwrap();
            w.finish().unwrap();
            let mut r = NpzReader::open(&path).unwrap();
            assert_eq!(r.member_names(), vec!["mask_0000000000.npy"]);
            let a = r.read_key("mask_0000000000").unwrap();
            assert_eq!(a.header.shape, vec![20, 30]);
            assert_eq!(a.data, data);
            let e = r.read_key("mask_0000000001").unwrap_err().to_string();
            assert!(
                e.contains("mask_0000000001.npy") && e.contains("mask_0000000000.npy"),
                "{e}"
            );
        }
    }

    #[test]
    fn not_a_zip_is_an_error() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("bad.npz");
        std::fs::write(&path, b"this is not a zip archive at all, just text").unwrap();
        let e = NpzReader::open(&path).unwrap_err().to_string();
        assert!(e.contains("bad.npz") && e.contains("zip"), "{e}");
    }
}
