//! A minimal, bounds-checked FlatBuffers reader: just what AEDAT 4 needs (tables, scalars,
//! strings, vectors of structs and of tables). Every access checks the buffer bounds and returns
//! an error text instead of panicking on corrupt data.

/// Result of a buffer access; the error says what was out of bounds.
pub(crate) type FbResult<T> = Result<T, String>;

fn bytes<const N: usize>(buf: &[u8], pos: usize) -> FbResult<[u8; N]> {
    pos.checked_add(N)
        .and_then(|end| buf.get(pos..end))
        .and_then(|s| s.try_into().ok())
        .ok_or_else(|| {
            format!(
                "flatbuffer read of {N} bytes at {pos} past its end ({} bytes)",
                buf.len()
            )
        })
}

/// Reads a little-endian u32 at `pos`.
pub(crate) fn u32_at(buf: &[u8], pos: usize) -> FbResult<u32> {
    bytes::<4>(buf, pos).map(u32::from_le_bytes)
}

fn u16_at(buf: &[u8], pos: usize) -> FbResult<u16> {
    bytes::<2>(buf, pos).map(u16::from_le_bytes)
}

fn i32_at(buf: &[u8], pos: usize) -> FbResult<i32> {
    bytes::<4>(buf, pos).map(i32::from_le_bytes)
}

/// The four-byte file identifier of a (non size-prefixed) buffer.
pub(crate) fn identifier(buf: &[u8]) -> FbResult<[u8; 4]> {
    bytes::<4>(buf, 4)
}

/// A table inside a buffer.
#[derive(Clone, Copy)]
pub(crate) struct Table<'a> {
    buf: &'a [u8],
    pos: usize,
    vtable: usize,
    vtable_len: usize,
}

impl<'a> Table<'a> {
    /// The root table of a (non size-prefixed) buffer.
    pub fn root(buf: &'a [u8]) -> FbResult<Self> {
        let pos = u32_at(buf, 0)? as usize;
        Self::at(buf, pos)
    }

    /// The table starting at `pos`.
    pub fn at(buf: &'a [u8], pos: usize) -> FbResult<Self> {
        let soffset = i32_at(buf, pos)? as i64;
        let vtable = pos as i64 - soffset;
        if vtable < 0 || vtable as usize >= buf.len() {
            return Err(format!(
                "flatbuffer table at {pos} has its vtable outside the buffer"
            ));
        }
        let vtable = vtable as usize;
        let vtable_len = u16_at(buf, vtable)? as usize;
        if vtable_len < 4 || vtable.saturating_add(vtable_len) > buf.len() {
            return Err(format!(
                "flatbuffer vtable at {vtable} has a bad length {vtable_len}"
            ));
        }
        Ok(Table {
            buf,
            pos,
            vtable,
            vtable_len,
        })
    }

    /// Position of field `index`'s data, `None` when the field is absent.
    fn field(&self, index: usize) -> FbResult<Option<usize>> {
        let entry = 4 + 2 * index;
        if entry + 2 > self.vtable_len {
            return Ok(None);
        }
        let offset = u16_at(self.buf, self.vtable + entry)? as usize;
        Ok(if offset == 0 {
            None
        } else {
            Some(self.pos + offset)
        })
    }

    fn scalar<const N: usize>(&self, index: usize) -> FbResult<Option<[u8; N]>> {
        match self.field(index)? {
            Some(pos) => bytes::<N>(self.buf, pos).map(Some),
            None => Ok(None),
        }
    }

    /// An i64 field, or `default`.
    pub fn i64(&self, index: usize, default: i64) -> FbResult<i64> {
        Ok(self.scalar::<8>(index)?.map_or(default, i64::from_le_bytes))
    }

    /// An i32 field, or `default`.
    pub fn i32(&self, index: usize, default: i32) -> FbResult<i32> {
        Ok(self.scalar::<4>(index)?.map_or(default, i32::from_le_bytes))
    }

    /// An f32 field, or `default`.
    pub fn f32(&self, index: usize, default: f32) -> FbResult<f32> {
        Ok(self.scalar::<4>(index)?.map_or(default, f32::from_le_bytes))
    }

    /// Position of the target of an offset field.
    fn indirect(&self, index: usize) -> FbResult<Option<usize>> {
        match self.field(index)? {
            Some(pos) => {
                let target = pos.checked_add(u32_at(self.buf, pos)? as usize);
                match target {
                    Some(t) if t < self.buf.len() => Ok(Some(t)),
                    _ => Err(format!("flatbuffer offset at {pos} points outside the buffer")),
                }
            }
            None => Ok(None),
        }
    }

    /// A vector field of `element_size`-byte elements: position of the first element and the
    /// element count, checked to lie inside the buffer. `None` when absent.
    pub fn vector(&self, index: usize, element_size: usize) -> FbResult<Option<(usize, usize)>> {
        let Some(pos) = self.indirect(index)? else {
            return Ok(None);
        };
        let len = u32_at(self.buf, pos)? as usize;
        let start = pos + 4;
        let end = len.checked_mul(element_size).and_then(|n| n.checked_add(start));
        match end {
            Some(end) if end <= self.buf.len() => Ok(Some((start, len))),
            _ => Err(format!(
                "flatbuffer vector of {len} x {element_size} bytes at {pos} runs past the buffer"
            )),
        }
    }

    /// A string field (UTF-8 checked), `None` when absent.
    pub fn string(&self, index: usize) -> FbResult<Option<&'a str>> {
        let Some((start, len)) = self.vector(index, 1)? else {
            return Ok(None);
        };
        std::str::from_utf8(&self.buf[start..start + len])
            .map(Some)
            .map_err(|e| format!("flatbuffer string at {start} is not UTF-8: {e}"))
    }

    /// Element `i` of a vector of tables starting at `start` (from [`Table::vector`] with
    /// element size 4).
    pub fn vector_table(&self, start: usize, i: usize) -> FbResult<Table<'a>> {
        let slot = start + 4 * i;
        let target = slot
            .checked_add(u32_at(self.buf, slot)? as usize)
            .ok_or_else(|| format!("flatbuffer offset at {slot} overflows"))?;
        Table::at(self.buf, target)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A hand-built buffer: root table at 12 with i32 field 0 = 7, field 1 absent, string field 2
    /// = "hi"; vtable at 24.
    fn sample() -> Vec<u8> {
        let mut b = Vec::new();
        b.extend_from_slice(&12u32.to_le_bytes()); // 0: root offset
        b.extend_from_slice(b"TEST"); // 4: identifier
        b.extend_from_slice(&[0; 4]); // 8: padding
        b.extend_from_slice(&(-12i32).to_le_bytes()); // 12: table, vtable at 12 - (-12) = 24
        b.extend_from_slice(&7i32.to_le_bytes()); // 16: field 0
        b.extend_from_slice(&16u32.to_le_bytes()); // 20: field 2 -> string at 36
        for v in [10u16, 12, 4, 0, 8] {
            b.extend_from_slice(&v.to_le_bytes()); // 24..34: vtable
        }
        b.extend_from_slice(&[0; 2]); // 34: padding
        b.extend_from_slice(&2u32.to_le_bytes()); // 36: string length
        b.extend_from_slice(b"hi");
        b
    }

    #[test]
    fn reads_fields_and_rejects_out_of_bounds() {
        let b = sample();
        let t = Table::root(&b).unwrap();
        assert_eq!(identifier(&b).unwrap(), *b"TEST");
        assert_eq!(t.i32(0, -1).unwrap(), 7);
        assert_eq!(t.i64(1, -5).unwrap(), -5);
        assert_eq!(t.string(2).unwrap(), Some("hi"));
        // A string whose length runs past the buffer is an error, not a panic.
        let mut bad = b.clone();
        bad[36..40].copy_from_slice(&1000u32.to_le_bytes());
        assert!(Table::root(&bad).unwrap().string(2).is_err());
        // A root offset past the end, a vtable outside the buffer, a cut buffer: errors.
        let mut bad = b.clone();
        bad[0..4].copy_from_slice(&5000u32.to_le_bytes());
        assert!(Table::root(&bad).is_err());
        let mut bad = b.clone();
        bad[12..16].copy_from_slice(&(-4000i32).to_le_bytes());
        assert!(Table::root(&bad).is_err());
        assert!(Table::root(&b[..3]).is_err());
        assert!(Table::root(&b[..20]).is_err());
    }
}
