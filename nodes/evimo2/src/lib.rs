//! Read and write EVIMO2 v2 sequence folders (npy/npz, pickled meta).

pub mod error;
pub mod meta;
pub mod npy;
pub mod npz;
pub mod pickle_write;
pub mod pylit;
pub mod reader;

pub use error::{Evimo2Error, Result};
