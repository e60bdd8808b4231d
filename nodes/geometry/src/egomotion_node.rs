//! The egomotion's node parameters: one block of names, defaults and docs for every node binary
//! that estimates the camera translation ([`EgomotionParams`]), and reading them back from the
//! node's config. Feature `node`.

use evseg_runtime::describe::Describe;
use evseg_runtime::{NodeConfig, RuntimeError};

use crate::egomotion::EgomotionParams;
use crate::svm::SvmParams;

/// Declares the egomotion parameters on `d` with the defaults of `defaults`.
pub fn describe_egomotion(d: Describe, defaults: &EgomotionParams) -> Describe {
    d.param("svm_c", defaults.svm.c, "SVM cost C (squared hinge)")
        .param(
            "egomotion_min_confidence",
            f64::from(defaults.min_confidence),
            "only flow above this confidence takes part in the egomotion",
        )
        .param(
            "egomotion_min_samples",
            defaults.min_samples,
            "fewest background events for an egomotion estimate",
        )
        .param(
            "refine_iterations",
            defaults.refine_iterations,
            "rounds of depth refinement after the SVM (0 = the SVM alone, as in the paper)",
        )
        .param(
            "depth_grid_cols",
            defaults.grid_cols,
            "columns of the grid of constant-depth cells of the refinement",
        )
        .param(
            "min_cell_samples",
            defaults.min_cell_samples,
            "cells with fewer samples are left out of the refinement",
        )
        .param(
            "egomotion_density_cell_px",
            defaults.density_cell_px,
            "cells over which the egomotion samples are density-normalized, pixels (0 = off)",
        )
        .param(
            "refine_huber_k",
            defaults.huber_k,
            "Huber constant of the egomotion's depth refinement, in robust residual scales (0 = plain least squares)",
        )
        .param(
            "egomotion_magnitude_weighting",
            defaults.magnitude_weighting,
            "weight egomotion samples by 1 / (n^2 + median n^2) (normal-flow error grows with its length)",
        )
        .param(
            "egomotion_clear_px",
            defaults.clear_px,
            "leave background events within about this many pixels of a non-background event out of the egomotion (0 = keep all)",
        )
        .param(
            "egomotion_max_samples",
            defaults.max_samples,
            "most samples of an egomotion estimate; more are thinned by a regular stride (0 = all)",
        )
}

/// Most columns of the refinement's depth grid: a cell per 2.5 px of a 640 px wide sensor
/// (the default is 8); the grid's memory grows with the square of it.
pub const MAX_DEPTH_GRID_COLS: usize = 256;

/// Reads the parameters declared by [`describe_egomotion`] from the node's config (the
/// launcher fills in the defaults, so each must be present).
pub fn egomotion_from_config(cfg: &NodeConfig) -> Result<EgomotionParams, RuntimeError> {
    let grid_cols: usize = cfg.param("depth_grid_cols")?;
    if !(1..=MAX_DEPTH_GRID_COLS).contains(&grid_cols) {
        return Err(RuntimeError::Param {
            node: cfg.node.clone(),
            name: "depth_grid_cols".into(),
            reason: format!("{grid_cols} is outside 1..={MAX_DEPTH_GRID_COLS}"),
        });
    }
    Ok(EgomotionParams {
        svm: SvmParams {
            c: cfg.param("svm_c")?,
            ..SvmParams::default()
        },
        min_confidence: cfg.param("egomotion_min_confidence")?,
        min_samples: cfg.param("egomotion_min_samples")?,
        refine_iterations: cfg.param("refine_iterations")?,
        grid_cols,
        min_cell_samples: cfg.param("min_cell_samples")?,
        density_cell_px: cfg.param("egomotion_density_cell_px")?,
        huber_k: cfg.param("refine_huber_k")?,
        magnitude_weighting: cfg.param("egomotion_magnitude_weighting")?,
        clear_px: cfg.param("egomotion_clear_px")?,
        max_samples: cfg.param("egomotion_max_samples")?,
        ..EgomotionParams::default()
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn config(params: serde_json::Map<String, serde_json::Value>) -> NodeConfig {
        NodeConfig::with_params("merger", params)
    }

    #[test]
    fn a_depth_grid_outside_its_range_is_refused_naming_the_parameter() {
        let description =
            describe_egomotion(Describe::new("evseg-test", "test"), &EgomotionParams::default()).build();
        for cols in [0u64, 257, 1_000_000_000] {
            let mut params: serde_json::Map<String, serde_json::Value> = description
                .params
                .iter()
                .map(|p| (p.name.clone(), p.default.clone()))
                .collect();
            params.insert("depth_grid_cols".into(), cols.into());
            let e = egomotion_from_config(&config(params)).unwrap_err().to_string();
            assert!(
                e.contains("parameter `depth_grid_cols`") && e.contains("1..=256"),
                "{e}"
            );
        }
    }

    #[test]
    fn declared_defaults_read_back_as_the_defaults() {
        let custom = EgomotionParams {
            min_confidence: 0.25,
            refine_iterations: 7,
            huber_k: 2.0,
            magnitude_weighting: false,
            clear_px: 12,
            max_samples: 500,
            ..EgomotionParams::default()
        };
        let description = describe_egomotion(Describe::new("evseg-test", "test"), &custom).build();
        let params = description
            .params
            .iter()
            .map(|p| (p.name.clone(), p.default.clone()))
            .collect();
        assert_eq!(egomotion_from_config(&config(params)).unwrap(), custom);
    }

    #[test]
    fn a_missing_or_mistyped_parameter_is_named() {
        let description =
            describe_egomotion(Describe::new("evseg-test", "test"), &EgomotionParams::default()).build();
        let mut params: serde_json::Map<_, _> = description
            .params
            .iter()
            .map(|p| (p.name.clone(), p.default.clone()))
            .collect();
        params.insert("refine_huber_k".into(), serde_json::json!("big"));
        let err = egomotion_from_config(&config(params.clone()))
            .unwrap_err()
            .to_string();
        assert!(err.contains("refine_huber_k"), "{err}");
        params.remove("svm_c");
        let err = egomotion_from_config(&config(params)).unwrap_err().to_string();
        assert!(err.contains("svm_c"), "{err}");
    }
}
