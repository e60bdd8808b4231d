//! The learned estimator's weights file: frequency vectors of the random-Fourier-feature
//! encoding and the bias-free MLP, in one little-endian binary file.
//!
//! # Format (version 1)
//!
//! Every number is little-endian; `f32` is IEEE 754 binary32.
//!
//! | offset | type | field |
//! |---|---|---|
//! | 0 | 8 bytes | magic `b"EVSEGNFW"` |
//! | 8 | u32 | version, 1 |
//! | 12 | u32 | `D`, the number of frequency vectors (the encoding has `2 D` features: `D` real parts then `D` imaginary parts) |
//! | 16 | u32 | `L`, the number of layers (>= 1) |
//! | 20 | u32 x (L + 1) | layer sizes `n_0 = 2 D, n_1, ..., n_L = 2` |
//! | .. | f32 | `radius_px`: the neighbourhood radius the network was trained with, pixels |
//! | .. | f32 | `alpha_xy`: scale of the spatial frequencies, radians per `radius_px` |
//! | .. | f32 | `alpha_t`: scale of the temporal frequencies, radians per unit of `tau` |
//! | .. | u64 | `seed` the frequencies and the training were drawn from |
//! | .. | f32 x D | `At`, temporal frequencies (radians per unit of `tau`, `tau` = time scaled to `[0, 2)` over the slice) |
//! | .. | f32 x D | `Ax`, spatial frequencies along x (radians per `dx / radius_px`) |
//! | .. | f32 x D | `Ay`, spatial frequencies along y (radians per `dy / radius_px`) |
//! | .. | f32 x (n_{k-1} n_k), k = 1..L | layer `k`'s weights, stored input-major: entry `[i][o]` at `i n_k + o` multiplies input `i` into output `o` |
//! | end - 8 | u64 | FNV-1a 64 hash of every byte before it |
//!
//! The file must end exactly after the hash. The MLP is `y = W_L^T relu(... relu(W_1^T x))`
//! (ReLU after every layer but the last, no biases); its output is the normal flow in units of
//! `radius_px` pixels per half slice (see [`crate::learned`]).

use std::path::{Path, PathBuf};

/// File magic.
pub const MAGIC: &[u8; 8] = b"EVSEGNFW";
/// The format version this crate reads and writes.
pub const VERSION: u32 = 1;
/// Largest accepted `D` and layer size (a sanity bound against corrupt headers).
pub const MAX_SIZE: u32 = 4096;

/// Errors reading or writing a weights file; every one names the file.
#[derive(Debug, thiserror::Error)]
pub enum WeightsError {
    /// The file cannot be read or written.
    #[error("weights file {path}: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// The cause.
        source: std::io::Error,
    },
    /// The file does not start with the magic.
    #[error("weights file {path}: not an evseg normal-flow weights file (bad magic)")]
    Magic {
        /// The file.
        path: PathBuf,
    },
    /// Unsupported version.
    #[error("weights file {path}: version {version}, this build reads version {VERSION}")]
    Version {
        /// The file.
        path: PathBuf,
        /// The version found.
        version: u32,
    },
    /// The file ends early.
    #[error("weights file {path}: truncated ({len} bytes, {needed} needed at least)")]
    Truncated {
        /// The file.
        path: PathBuf,
        /// Its length, bytes.
        len: usize,
        /// Bytes needed.
        needed: usize,
    },
    /// Bytes after the hash.
    #[error("weights file {path}: {extra} unexpected bytes after the end")]
    Trailing {
        /// The file.
        path: PathBuf,
        /// Extra bytes.
        extra: usize,
    },
    /// The hash does not match (corrupt file).
    #[error("weights file {path}: checksum mismatch (stored {stored:016x}, computed {computed:016x})")]
    Checksum {
        /// The file.
        path: PathBuf,
        /// Stored hash.
        stored: u64,
        /// Hash of the content.
        computed: u64,
    },
    /// Inconsistent header or values.
    #[error("weights file {path}: {what}")]
    Invalid {
        /// The file.
        path: PathBuf,
        /// What is wrong.
        what: String,
    },
}

/// The weights of the learned estimator (see the module docs for the meaning of each field).
#[derive(Debug, Clone, PartialEq)]
pub struct LearnedWeights {
    /// Neighbourhood radius the network was trained with, pixels.
    pub radius_px: f32,
    /// Scale of the spatial frequencies (radians per `radius_px`), for the record.
    pub alpha_xy: f32,
    /// Scale of the temporal frequencies (radians per unit of `tau`), for the record.
    pub alpha_t: f32,
    /// Seed of the frequencies and of the training.
    pub seed: u64,
    /// Temporal frequencies, radians per unit of `tau` (`D` entries).
    pub at: Vec<f32>,
    /// Spatial frequencies along x, radians per `dx / radius_px` (`D` entries).
    pub ax: Vec<f32>,
    /// Spatial frequencies along y, radians per `dy / radius_px` (`D` entries).
    pub ay: Vec<f32>,
    /// Layer sizes, `[2 D, hidden..., 2]`.
    pub sizes: Vec<usize>,
    /// Weights of each layer, input-major (`[i][o]` at `i * n_out + o`).
    pub layers: Vec<Vec<f32>>,
}

/// FNV-1a 64-bit hash.
pub fn fnv1a64(bytes: &[u8]) -> u64 {
    let mut h: u64 = 0xcbf2_9ce4_8422_2325;
    for &b in bytes {
        h ^= u64::from(b);
        h = h.wrapping_mul(0x0000_0100_0000_01b3);
    }
    h
}

struct Reader<'a> {
    bytes: &'a [u8],
    pos: usize,
    path: &'a Path,
}

impl Reader<'_> {
    fn take(&mut self, n: usize) -> Result<&[u8], WeightsError> {
        let end = self.pos.checked_add(n).filter(|&e| e <= self.bytes.len());
        let Some(end) = end else {
            return Err(WeightsError::Truncated {
                path: self.path.to_path_buf(),
                len: self.bytes.len(),
                needed: self.pos.saturating_add(n).saturating_add(8),
            });
        };
        let s = &self.bytes[self.pos..end];
        self.pos = end;
        Ok(s)
    }
    fn u32(&mut self) -> Result<u32, WeightsError> {
        let b = self.take(4)?;
        Ok(u32::from_le_bytes([b[0], b[1], b[2], b[3]]))
    }
    fn u64(&mut self) -> Result<u64, WeightsError> {
        let b = self.take(8)?;
        let mut a = [0u8; 8];
        a.copy_from_slice(b);
        Ok(u64::from_le_bytes(a))
    }
    fn f32(&mut self) -> Result<f32, WeightsError> {
        Ok(f32::from_bits(self.u32()?))
    }
    fn f32s(&mut self, n: usize) -> Result<Vec<f32>, WeightsError> {
        let b = self.take(n.saturating_mul(4))?;
        Ok(b.chunks_exact(4)
            .map(|c| f32::from_le_bytes([c[0], c[1], c[2], c[3]]))
            .collect())
    }
}

impl LearnedWeights {
    /// `D`, the number of frequency vectors.
    pub fn d(&self) -> usize {
        self.at.len()
    }

    /// Reads and checks a weights file.
    pub fn load(path: impl AsRef<Path>) -> Result<Self, WeightsError> {
        let path = path.as_ref();
        let bytes = std::fs::read(path).map_err(|source| WeightsError::Io {
            path: path.to_path_buf(),
            source,
        })?;
        Self::from_bytes(&bytes, path)
    }

    /// Parses the bytes of a weights file; `path` is only used in error messages.
    pub fn from_bytes(bytes: &[u8], path: &Path) -> Result<Self, WeightsError> {
        let invalid = |what: String| WeightsError::Invalid {
            path: path.to_path_buf(),
            what,
        };
        let mut r = Reader { bytes, pos: 0, path };
        if r.take(8)? != MAGIC {
            return Err(WeightsError::Magic {
                path: path.to_path_buf(),
            });
        }
        let version = r.u32()?;
        if version != VERSION {
            return Err(WeightsError::Version {
                path: path.to_path_buf(),
                version,
            });
        }
        let d = r.u32()?;
        let n_layers = r.u32()?;
        if d == 0 || d > MAX_SIZE {
            return Err(invalid(format!("D = {d} outside 1..={MAX_SIZE}")));
        }
        if n_layers == 0 || n_layers > 16 {
            return Err(invalid(format!("{n_layers} layers, 1..=16 expected")));
        }
        let mut sizes = Vec::with_capacity(n_layers as usize + 1);
        for _ in 0..=n_layers {
            let s = r.u32()?;
            if s == 0 || s > MAX_SIZE {
                return Err(invalid(format!("layer size {s} outside 1..={MAX_SIZE}")));
            }
            sizes.push(s as usize);
        }
        if sizes[0] != 2 * d as usize {
            return Err(invalid(format!("input size {} is not 2 D = {}", sizes[0], 2 * d)));
        }
        if sizes[n_layers as usize] != 2 {
            return Err(invalid(format!(
                "output size {} is not 2",
                sizes[n_layers as usize]
            )));
        }
        let radius_px = r.f32()?;
        let alpha_xy = r.f32()?;
        let alpha_t = r.f32()?;
        let seed = r.u64()?;
        if !(1.0..=64.0).contains(&radius_px) {
            return Err(invalid(format!("radius {radius_px} px outside [1, 64]")));
        }
        let d = d as usize;
        let at = r.f32s(d)?;
        let ax = r.f32s(d)?;
        let ay = r.f32s(d)?;
        let mut layers = Vec::with_capacity(n_layers as usize);
        for k in 1..sizes.len() {
            layers.push(r.f32s(sizes[k - 1] * sizes[k])?);
        }
        let content_end = r.pos;
        let stored = r.u64()?;
        if r.pos != bytes.len() {
            return Err(WeightsError::Trailing {
                path: path.to_path_buf(),
                extra: bytes.len() - r.pos,
            });
        }
        let computed = fnv1a64(&bytes[..content_end]);
        if stored != computed {
            return Err(WeightsError::Checksum {
                path: path.to_path_buf(),
                stored,
                computed,
            });
        }
        let finite = |v: &[f32]| v.iter().all(|x| x.is_finite());
        if !(finite(&at) && finite(&ax) && finite(&ay) && layers.iter().all(|l| finite(l))) {
            return Err(invalid("non-finite frequency or weight".into()));
        }
        Ok(Self {
            radius_px,
            alpha_xy,
            alpha_t,
            seed,
            at,
            ax,
            ay,
            sizes,
            layers,
        })
    }

    /// Checks that the sizes agree with each other (for weights built in memory).
    pub fn validate(&self) -> Result<(), String> {
        let d = self.at.len();
        if d == 0 || self.ax.len() != d || self.ay.len() != d {
            return Err(format!(
                "frequency vectors of lengths {}, {}, {}",
                self.at.len(),
                self.ax.len(),
                self.ay.len()
            ));
        }
        if self.sizes.len() < 2 || self.sizes[0] != 2 * d || self.sizes.last() != Some(&2) {
            return Err(format!("layer sizes {:?} for D = {d}", self.sizes));
        }
        if self.layers.len() + 1 != self.sizes.len() {
            return Err(format!("{} layers for sizes {:?}", self.layers.len(), self.sizes));
        }
        for (k, l) in self.layers.iter().enumerate() {
            if l.len() != self.sizes[k] * self.sizes[k + 1] {
                return Err(format!("layer {} has {} weights", k + 1, l.len()));
            }
        }
        Ok(())
    }

    /// The file's bytes.
    pub fn to_bytes(&self) -> Vec<u8> {
        let mut b = Vec::new();
        b.extend_from_slice(MAGIC);
        b.extend_from_slice(&VERSION.to_le_bytes());
        b.extend_from_slice(&(self.at.len() as u32).to_le_bytes());
        b.extend_from_slice(&(self.layers.len() as u32).to_le_bytes());
        for &s in &self.sizes {
            b.extend_from_slice(&(s as u32).to_le_bytes());
        }
        for v in [self.radius_px, self.alpha_xy, self.alpha_t] {
            b.extend_from_slice(&v.to_le_bytes());
        }
        b.extend_from_slice(&self.seed.to_le_bytes());
        for v in self
            .at
            .iter()
            .chain(&self.ax)
            .chain(&self.ay)
            .chain(self.layers.iter().flatten())
        {
            b.extend_from_slice(&v.to_le_bytes());
        }
        let h = fnv1a64(&b);
        b.extend_from_slice(&h.to_le_bytes());
        b
    }

    /// Writes the file.
    pub fn save(&self, path: impl AsRef<Path>) -> Result<(), WeightsError> {
        let path = path.as_ref();
        std::fs::write(path, self.to_bytes()).map_err(|source| WeightsError::Io {
            path: path.to_path_buf(),
            source,
        })
    }
}
