//! Block-wise file reading with byte offsets, for the word-oriented binary formats.

use std::fs::File;
use std::io::{ErrorKind, Read, Seek, SeekFrom};
use std::path::{Path, PathBuf};

use crate::DecodeError;

/// Reads a file in blocks of a fixed size and keeps track of the file offset of every byte.
pub(crate) struct BlockReader {
    file: File,
    path: PathBuf,
    buf: Vec<u8>,
    /// Next unread byte of `buf`.
    pos: usize,
    /// Number of valid bytes in `buf`.
    len: usize,
    /// File offset of `buf[0]`.
    buf_offset: u64,
}

impl BlockReader {
    /// Opens `path` and positions the reader at `start` bytes (after a header). The block size is
    /// at least 64 bytes.
    pub fn open(path: &Path, start: u64, block_bytes: usize) -> Result<Self, DecodeError> {
        let io_error = |source| DecodeError::Io {
            path: path.to_path_buf(),
            offset: start,
            source,
        };
        let mut file = File::open(path).map_err(io_error)?;
        file.seek(SeekFrom::Start(start)).map_err(io_error)?;
        Ok(BlockReader {
            file,
            path: path.to_path_buf(),
            buf: vec![0; block_bytes.max(64)],
            pos: 0,
            len: 0,
            buf_offset: start,
        })
    }

    /// The unread bytes of the current block.
    #[inline]
    pub fn available(&self) -> &[u8] {
        &self.buf[self.pos..self.len]
    }

    /// Marks `n` bytes of [`BlockReader::available`] as read.
    #[inline]
    pub fn consume(&mut self, n: usize) {
        self.pos = (self.pos + n).min(self.len);
    }

    /// File offset of the next unread byte.
    #[inline]
    pub fn offset(&self) -> u64 {
        self.buf_offset + self.pos as u64
    }

    /// The file's path.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// Keeps the unread bytes, moved to the front, and reads more after them. Returns `Ok(false)`
    /// when the file has no more bytes.
    pub fn refill(&mut self) -> Result<bool, DecodeError> {
        if self.pos > 0 {
            self.buf.copy_within(self.pos..self.len, 0);
            self.buf_offset += self.pos as u64;
            self.len -= self.pos;
            self.pos = 0;
        }
        if self.len == self.buf.len() {
            // A full block of unread bytes: nothing to make room for (callers consume first).
            return Ok(true);
        }
        loop {
            match self.file.read(&mut self.buf[self.len..]) {
                Ok(0) => return Ok(false),
                Ok(n) => {
                    self.len += n;
                    return Ok(true);
                }
                Err(error) if error.kind() == ErrorKind::Interrupted => continue,
                Err(source) => {
                    return Err(DecodeError::Io {
                        path: self.path.clone(),
                        offset: self.buf_offset + self.len as u64,
                        source,
                    });
                }
            }
        }
    }
}
