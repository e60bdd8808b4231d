//! Per-event columns on the wire as one block of little-endian bytes each, instead of one
//! bincode value per element: encoding and decoding become a copy, which is what keeps the
//! multi-process graph close to in-process speed. Used through `#[serde(with = ...)]` on the
//! message fields; the format is pinned by the golden-bytes tests in [`crate::codec`].

use serde::de::{Error, Visitor};
use serde::{Deserializer, Serializer};

macro_rules! column {
    ($name:ident, $t:ty, $n:expr) => {
        /// Serde adapter for a `Vec` of this element type as little-endian bytes.
        pub mod $name {
            use super::*;

            /// Writes the column as one byte block.
            pub fn serialize<S: Serializer>(v: &[$t], s: S) -> Result<S::Ok, S::Error> {
                // On little-endian machines the values' memory is already the wire format.
                #[cfg(target_endian = "little")]
                {
                    s.serialize_bytes(bytemuck::cast_slice(v))
                }
                #[cfg(not(target_endian = "little"))]
                {
                    let mut bytes = Vec::with_capacity(v.len() * $n);
                    for x in v {
                        bytes.extend_from_slice(&x.to_le_bytes());
                    }
                    s.serialize_bytes(&bytes)
                }
            }

            struct V;

            impl<'de> Visitor<'de> for V {
                type Value = Vec<$t>;

                fn expecting(&self, f: &mut std::fmt::Formatter) -> std::fmt::Result {
                    write!(f, "a byte block of {}-byte little-endian values", $n)
                }

                fn visit_bytes<E: Error>(self, b: &[u8]) -> Result<Self::Value, E> {
                    if b.len() % $n != 0 {
                        return Err(E::custom(format!(
                            "column of {} bytes is not a multiple of {}",
                            b.len(),
                            $n
                        )));
                    }
                    #[cfg(target_endian = "little")]
                    {
                        // The wire format is the values' memory: one copy.
                        let mut v: Vec<$t> = vec![<$t>::default(); b.len() / $n];
                        bytemuck::cast_slice_mut::<$t, u8>(&mut v).copy_from_slice(b);
                        Ok(v)
                    }
                    #[cfg(not(target_endian = "little"))]
                    {
                        Ok(b.chunks_exact($n)
                            .map(|c| <$t>::from_le_bytes(c.try_into().unwrap_or([0; $n])))
                            .collect())
                    }
                }

                fn visit_borrowed_bytes<E: Error>(self, b: &'de [u8]) -> Result<Self::Value, E> {
                    self.visit_bytes(b)
                }

                fn visit_byte_buf<E: Error>(self, b: Vec<u8>) -> Result<Self::Value, E> {
                    self.visit_bytes(&b)
                }
            }

            /// Reads a column written by [`serialize`].
            pub fn deserialize<'de, D: Deserializer<'de>>(d: D) -> Result<Vec<$t>, D::Error> {
                d.deserialize_bytes(V)
            }
        }
    };
}

column!(f64s, f64, 8);
column!(f32s, f32, 4);
column!(u32s, u32, 4);
column!(u16s, u16, 2);

/// Serde adapter for a `Vec<u8>` as one byte block.
pub mod u8s {
    use super::*;

    /// Writes the bytes as one block.
    pub fn serialize<S: Serializer>(v: &[u8], s: S) -> Result<S::Ok, S::Error> {
        s.serialize_bytes(v)
    }

    struct V;

    impl<'de> Visitor<'de> for V {
        type Value = Vec<u8>;

        fn expecting(&self, f: &mut std::fmt::Formatter) -> std::fmt::Result {
            write!(f, "a byte block")
        }

        fn visit_bytes<E: Error>(self, b: &[u8]) -> Result<Self::Value, E> {
            Ok(b.to_vec())
        }

        fn visit_byte_buf<E: Error>(self, b: Vec<u8>) -> Result<Self::Value, E> {
            Ok(b)
        }
    }

    /// Reads a block written by [`serialize`].
    pub fn deserialize<'de, D: Deserializer<'de>>(d: D) -> Result<Vec<u8>, D::Error> {
        d.deserialize_bytes(V)
    }
}
