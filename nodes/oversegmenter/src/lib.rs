//! Over-segmentation of a slice (the paper's section 3.2, "Initial Normal Flow Clustering"):
//! k-means on the per-event features `[x, y, lambda * tau * nx, lambda * tau * ny]`.
//!
//! Units (the paper does not give them, so they are chosen here and documented):
//! - `x, y`: undistorted normalized coordinates of the event's pixel (focal length 1);
//! - `(nx, ny)`: the event's normal flow vector, normalized units per second;
//! - `tau` ([`OversegParams::flow_time_scale_s`], default 1 s) turns the flow into a distance.
//!
//! With `tau = 1 s` the features are, up to the common factor `f` (focal length in pixels), the
//! same as "undistorted pixel coordinates and flow in pixels per second", the units of the public
//! normal-flow code the paper builds on; k-means is invariant to a common scale, so `lambda = 0.5`
//! means: 1 px/s of flow difference weighs as much as 0.5 px of distance. On a 640 px wide
//! sensor with flows of a few hundred px/s, position and motion then contribute comparably.
//!
//! Events without a valid flow (confidence not above [`OversegParams::min_confidence`], or a
//! non-finite component) are not clustered; their id is `u16::MAX`.

#![warn(missing_docs)]

pub mod kmeans;
pub mod rng;

use evseg_geometry::TableCache;
use evseg_schemas::align::{AlignError, check_flow};
use evseg_schemas::{CameraInfo, Clusters, Events, NormalFlow};

pub use kmeans::{KMeans, KMeansParams, kmeans};

/// Id of an event that was not clustered.
pub const UNASSIGNED: u16 = u16::MAX;

/// Over-segmentation settings.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct OversegParams {
    /// Number of clusters (default 30, the paper's section 3.2).
    pub k: usize,
    /// Weight of the flow features against position (default 0.5, the paper's section 3.2).
    pub lambda: f64,
    /// Seconds that turn flow (normalized units/s) into a distance (default 1 s; see the crate
    /// docs for why this makes the paper's `lambda` meaningful).
    pub flow_time_scale_s: f64,
    /// Flow with confidence at or below this is invalid (default 0: the NormalFlow convention
    /// "0 = no estimate").
    pub min_confidence: f32,
    /// Most Lloyd iterations (see [`KMeansParams::max_iter`]).
    pub max_iter: usize,
    /// Random seed (seeding, subsampling); the same seed gives the same clusters.
    pub seed: u64,
    /// Largest subsample used for seeding and iterations (see [`KMeansParams::max_samples`]).
    pub max_samples: usize,
}

impl Default for OversegParams {
    fn default() -> Self {
        let km = KMeansParams::default();
        Self {
            k: 30,
            lambda: 0.5,
            flow_time_scale_s: 1.0,
            min_confidence: 0.0,
            max_iter: km.max_iter,
            seed: km.seed,
            max_samples: km.max_samples,
        }
    }
}

/// Invalid parameters or malformed input.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum OversegError {
    /// A parameter is out of range.
    #[error(transparent)]
    Param(#[from] evseg_schemas::params::ParamError),
    /// A per-event input does not fit its slice.
    #[error(transparent)]
    Input(#[from] AlignError),
}

/// The over-segmentation stage; keeps the undistortion table of the last camera seen.
#[derive(Debug, Clone)]
pub struct Oversegmenter {
    params: OversegParams,
    table: TableCache,
}

impl Oversegmenter {
    /// A stage with `params`, checked.
    pub fn new(params: OversegParams) -> Result<Self, OversegError> {
        let bad = |name, value: String, why| {
            Err(OversegError::Param(evseg_schemas::params::ParamError {
                name,
                value,
                why,
            }))
        };
        if params.k == 0 || params.k >= UNASSIGNED as usize {
            return bad(
                "k",
                params.k.to_string(),
                "must be in 1..=65534 (65535 marks events without flow)",
            );
        }
        if !(params.lambda.is_finite() && params.lambda >= 0.0) {
            return bad("lambda", params.lambda.to_string(), "must be finite and >= 0");
        }
        if !(params.flow_time_scale_s.is_finite() && params.flow_time_scale_s >= 0.0) {
            return bad(
                "flow_time_scale_s",
                params.flow_time_scale_s.to_string(),
                "must be finite and >= 0",
            );
        }
        if params.max_samples == 0 {
            return bad("max_samples", "0".into(), "must be positive");
        }
        if let Some(problem) = evseg_geometry::min_confidence_problem(params.min_confidence) {
            return bad("min_confidence", params.min_confidence.to_string(), problem);
        }
        Ok(Self {
            params,
            table: TableCache::default(),
        })
    }

    /// The settings.
    pub fn params(&self) -> &OversegParams {
        &self.params
    }

    /// Clusters the events of one slice (`camera`, `events`) with their normal `flow`.
    pub fn segment(
        &mut self,
        camera: &CameraInfo,
        events: &Events,
        flow: &NormalFlow,
    ) -> Result<Clusters, OversegError> {
        check_flow(events, flow)?;
        let p = self.params;
        let scale = p.lambda * p.flow_time_scale_s;
        let table = self.table.get(camera);
        let mut feats = Vec::with_capacity(events.len());
        let mut index = Vec::with_capacity(events.len());
        for i in 0..events.len() {
            table.prefetch_ahead(&events.x, &events.y, i);
            let (u, v) = (events.x[i], events.y[i]);
            let [x, y] = table.event(i, u, v)?;
            let (nx, ny, c) = (flow.nx[i], flow.ny[i], flow.confidence[i]);
            if !(c > p.min_confidence && nx.is_finite() && ny.is_finite()) {
                continue;
            }
            feats.push([
                f64::from(x),
                f64::from(y),
                scale * f64::from(nx),
                scale * f64::from(ny),
            ]);
            index.push(i);
        }
        let km = kmeans(
            &feats,
            &KMeansParams {
                k: p.k,
                max_iter: p.max_iter,
                seed: p.seed,
                max_samples: p.max_samples,
            },
        );
        let mut id = vec![UNASSIGNED; events.len()];
        for (&i, &a) in index.iter().zip(&km.assignment) {
            // a < centers.len() <= k < u16::MAX (checked in `new`).
            id[i] = a as u16;
        }
        Ok(Clusters {
            id,
            count: km.centers.len() as u16,
        })
    }
}

#[cfg(test)]
mod tests;
