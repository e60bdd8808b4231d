//! `evseg-planar-segmenter`: preliminary foreground/background split by the residuals of a
//! planar normal-flow fit (paper section 3.3).

use std::process::ExitCode;

use evseg_geometry::RotationRate;
use evseg_geometry::rotation::{SLOPE_DEFAULT, SLOPE_PARAM, SLOPE_PARAM_DOC};
use evseg_planar_segmenter::{FitParams, PlanarParams, PlanarSegmenter, PreviousParams, Robust};
use evseg_runtime::describe::Describe;
use evseg_runtime::{BoxError, Inputs, NodeConfig, Outputs, Stage, run_stage};
use evseg_schemas::{CoarseSegmentation, NormalFlow, Residuals, Slice};

struct Node {
    segmenter: PlanarSegmenter,
    /// [`evseg_geometry::rotation::SLOPE_PARAM`].
    rate_slope: bool,
}

impl Stage for Node {
    fn process(&mut self, input: &Inputs, out: &mut Outputs) -> Result<(), BoxError> {
        let slice: Slice = input.get("slices")?;
        let flow: NormalFlow = input.get("flow")?;
        let rate = RotationRate::of_slice(&slice, input.span(), self.rate_slope);
        let previous: Option<CoarseSegmentation> = input.get_opt("previous")?;
        // Group 0 is the merged background; unassigned events (no cluster) count as background.
        let labels: Option<Vec<u32>> = previous.map(|c| {
            c.group
                .iter()
                .map(|&g| u32::from(g != 0 && g != CoarseSegmentation::UNASSIGNED))
                .collect()
        });
        let r = self.segmenter.segment_with_previous(
            &slice.camera,
            &slice.events,
            &flow,
            rate,
            labels.as_deref(),
        )?;
        tracing::debug!(
            slice = input.seq(),
            fitted = r.fitted_events,
            derotated = r.derotated,
            previous_applied = r.previous_applied,
            foreground = r.has_foreground,
            "planar fit"
        );
        let (t0, t1) = input.span();
        out.send("residuals", input.seq(), t0, t1, &r.residuals)?;
        Ok(())
    }
}

/// The `robust` parameter's name of `r` (the inverse of [`robust_from`] without its threshold).
fn robust_name(r: Robust) -> &'static str {
    match r {
        Robust::LeastSquares => "least_squares",
        Robust::Huber { .. } => "huber",
        Robust::Tukey { .. } => "tukey",
    }
}

fn robust_from(name: &str, threshold: Option<f64>) -> Result<Robust, BoxError> {
    Ok(match name {
        "least_squares" => Robust::LeastSquares,
        "huber" => Robust::Huber {
            k: threshold.unwrap_or(1.345),
        },
        "tukey" => Robust::Tukey {
            c: threshold.unwrap_or(4.685),
        },
        other => {
            return Err(format!("robust must be least_squares, huber or tukey, got {other:?}").into());
        }
    })
}

fn main() -> ExitCode {
    let d = PlanarParams::default();
    let description = Describe::new(
        "evseg-planar-segmenter",
        "Planar (8-parameter) normal-flow fit after IMU derotation; smoothed residuals, 2-means \
         into background/foreground (paper section 3.3)",
    )
    .input::<Slice>("slices", "event slices (omega: IMU rotation rate, camera frame)")
    .input::<NormalFlow>("flow", "per-event normal flow of the same slices")
    .optional_input::<CoarseSegmentation>(
        "previous",
        "the background merger's output of the previous slice (wire with feedback: true): its \
         foreground (groups other than 0) is left out of the fit",
    )
    .output::<Residuals>(
        "residuals",
        "residual per event (normalized units/s, NaN without flow), background flag, model = the \
         8 translational plane-flow parameters a (empty when the fit failed)",
    )
    .param(
        "min_confidence",
        f64::from(d.min_confidence),
        "flow at or below this confidence is invalid",
    )
    .param(
        "derotate",
        d.derotate,
        "subtract the IMU rotational flow before the fit",
    )
    .param(
        "robust",
        robust_name(d.fit.robust),
        "least_squares (the paper), huber or tukey (iteratively reweighted)",
    )
    .param(
        "robust_threshold",
        serde_json::Value::Null,
        "weight threshold in robust standard deviations (default huber 1.345, tukey 4.685)",
    )
    .param(
        "robust_needs_previous",
        d.robust_needs_previous,
        "use the robust fit only where the previous slice's foreground was left out of the fit (least squares otherwise)",
    )
    .param(
        "fit_memory",
        d.fit_memory,
        "weight of the previous slice's fit as a prior on this slice's, as a fraction of this slice's own fit weight (0 = off, the paper)",
    )
    .param(
        "fit_memory_gap_s",
        d.fit_memory_gap_s,
        "the previous fit is a prior only when its slice ended at most this long before this slice's first event, seconds",
    )
    .param(
        "start_centre_weight",
        d.start_centre_weight,
        "in a slice fitted without the previous foreground and the previous fit (the first), the weight of the view's centre, rising linearly to 1 at the border (1 = off)",
    )
    .param(SLOPE_PARAM, SLOPE_DEFAULT, SLOPE_PARAM_DOC)
    .param("robust_iterations", d.fit.iterations, "reweighting rounds of a robust fit, at most 1000")
    .param("ridge", d.fit.ridge, "Tikhonov regularization per equation")
    .param("cell_px", d.cell_px, "smoothing grid cell, pixels")
    .param(
        "residual_length_k",
        d.residual_length_k,
        "residuals scaled by (1 + k) n_med / (n + k n_med) before smoothing and the split: long flows' residuals count less (0 = absolute residuals, the paper)",
    )
    .param(
        "sigma_px",
        d.sigma_px,
        "Gaussian smoothing standard deviation, pixels",
    )
    .param(
        "sigma_reference_focal_px",
        d.sigma_reference_focal_px,
        "focal length (px) at which sigma_px holds; other cameras smooth over the same angle (0 = sigma_px as is)",
    )
    .param(
        "min_center_gap",
        d.min_center_gap,
        "2-means centres closer than this (normalized units/s) = no foreground",
    )
    .param(
        "split_power",
        d.split_power,
        "the 2-means split runs on smoothed residuals to this power (1 = linear, the paper; 0 = logarithms)",
    )
    .param("two_means_iter", d.two_means_iter, "most 2-means iterations, 1..=10000")
    .param(
        "classify_invalid",
        d.classify_invalid,
        "label events without flow by the smoothed residual around them",
    )
    .param(
        "min_support",
        d.min_support,
        "support needed to label an event without flow",
    )
    .param(
        "previous_weight",
        d.previous.weight,
        "fit weight of the events where the previous slice's foreground was (1 = off, 0 = left out)",
    )
    .param(
        "previous_cell_px",
        d.previous.cell_px,
        "cell of the previous-foreground mask, pixels",
    )
    .param(
        "previous_dilate_px",
        d.previous.dilate_px,
        "dilation of the previous-foreground mask, pixels",
    )
    .param(
        "previous_min_free_share",
        d.previous.min_free_share,
        "the mask is used only when at least this share of the fit's events lies outside it",
    )
    .param(
        "density_cell_px",
        d.density_cell_px,
        "cells over which the fit is density-normalized, pixels (0 = per-event weights)",
    )
    .build();
    run_stage(description, |cfg: &NodeConfig| {
        let robust: String = cfg.param("robust")?;
        let params = PlanarParams {
            min_confidence: cfg.param("min_confidence")?,
            derotate: cfg.param("derotate")?,
            fit: FitParams {
                robust: robust_from(&robust, cfg.param_opt("robust_threshold")?)?,
                iterations: cfg.param("robust_iterations")?,
                ridge: cfg.param("ridge")?,
            },
            cell_px: cfg.param("cell_px")?,
            sigma_px: cfg.param("sigma_px")?,
            sigma_reference_focal_px: cfg.param("sigma_reference_focal_px")?,
            residual_length_k: cfg.param("residual_length_k")?,
            min_center_gap: cfg.param("min_center_gap")?,
            split_power: cfg.param("split_power")?,
            robust_needs_previous: cfg.param("robust_needs_previous")?,
            fit_memory: cfg.param("fit_memory")?,
            fit_memory_gap_s: cfg.param("fit_memory_gap_s")?,
            start_centre_weight: cfg.param("start_centre_weight")?,
            two_means_iter: cfg.param("two_means_iter")?,
            classify_invalid: cfg.param("classify_invalid")?,
            min_support: cfg.param("min_support")?,
            density_cell_px: cfg.param("density_cell_px")?,
            previous: PreviousParams {
                weight: cfg.param("previous_weight")?,
                cell_px: cfg.param("previous_cell_px")?,
                dilate_px: cfg.param("previous_dilate_px")?,
                min_free_share: cfg.param("previous_min_free_share")?,
            },
        };
        Ok(Node {
            segmenter: PlanarSegmenter::new(params)?,
            rate_slope: cfg.param(SLOPE_PARAM)?,
        })
    })
}
