//! Warping the previous slice's segmentation to the current slice (paper section 3.4,
//! "Background Warping and Matching").
//!
//! The previous background's motion is modelled as the paper says, "a planar motion model with
//! constant depth": the 8-parameter planar flow `C(x) a` fitted to the previous background's
//! derotated normal flow, plus the previous IMU rotation `B(x) w`. Every previous event is moved
//! by that flow over the time between the two slices' centres and dropped into a background or
//! a foreground occupancy grid by its previous label. Foreground events are warped with the
//! background's motion too (their own motion is not known here); only their rough place matters.

use evseg_geometry::{Camera, FlowSample, UndistortTable, planar_flow, rotational_flow};
use evseg_planar_segmenter::{Equation, FitParams, fit_planar};
use evseg_schemas::CameraInfo;

use evseg_geometry::CellGrid;

/// What the merger keeps of a slice for the next one.
#[derive(Debug, Clone)]
pub struct PreviousSlice {
    /// Camera of the slice.
    pub camera: CameraInfo,
    /// Event columns, pixels.
    pub x: Vec<u16>,
    /// Event rows, pixels.
    pub y: Vec<u16>,
    /// The slice's flow samples (derotated when a rotation rate was known).
    pub samples: Vec<FlowSample>,
    /// Rotation rate of the slice, rad/s, camera frame.
    pub omega: Option<[f64; 3]>,
    /// Centre of the slice's time window, seconds.
    pub t_mid: f64,
    /// Translation direction estimated for the slice (camera frame, unit), if any.
    pub direction: Option<[f64; 3]>,
    /// Per event: its cluster was clearly not explained by the camera's motion (relative
    /// residual at least [`crate::BackgroundParams::moving_relres`]).
    pub moving: Vec<bool>,
    /// Per event: its cluster was confirmed foreground (see
    /// [`crate::BackgroundParams::silent_warp_needs_confirmation`]; all true when that is off).
    pub confirmed: Vec<bool>,
    /// Consecutive slices up to and including this one whose planar vote was silent
    /// ([`crate::BackgroundParams::planar_silent_share`]).
    pub silent_run: u32,
}

/// The previous segmentation moved to the current time.
#[derive(Debug, Clone)]
pub struct WarpedPrevious {
    /// Warped previous background events per cell, dilated by one cell.
    pub background: CellGrid,
    /// Warped previous foreground events per cell, dilated by one cell.
    pub foreground: CellGrid,
    /// Warped previous foreground events whose cluster clearly moved
    /// ([`PreviousSlice::moving`]), per cell, dilated by one cell.
    pub moving_foreground: CellGrid,
    /// Warped previous foreground events of confirmed clusters ([`PreviousSlice::confirmed`]),
    /// per cell, dilated by one cell.
    pub confirmed_foreground: CellGrid,
    /// The planar model used (`None`: too few background samples, rotation only).
    pub model: Option<[f64; 8]>,
}

/// Warps `prev`, whose final per-event labels are `labels` (0 = background), to time `t_mid`
/// (seconds) on grids of `cell_px` pixels. `table` is the undistortion table of `prev.camera`.
/// `None` when the labels do not fit the previous events.
pub fn warp_previous(
    prev: &PreviousSlice,
    labels: &[u32],
    table: &UndistortTable,
    t_mid: f64,
    cell_px: u16,
) -> Option<WarpedPrevious> {
    if labels.len() != prev.x.len() {
        return None;
    }
    let eqs: Vec<Equation> = prev
        .samples
        .iter()
        .filter(|s| labels[s.index] == 0)
        .map(|s| Equation::new(s.x, s.y, s.n0, s.n_derot))
        .collect();
    let model = fit_planar(&eqs, &FitParams::default());
    let dt = t_mid - prev.t_mid;
    let camera = Camera::new(&prev.camera);
    let (w, h) = (prev.camera.width, prev.camera.height);
    let mut background = CellGrid::new(w, h, cell_px);
    let mut foreground = CellGrid::new(w, h, cell_px);
    let mut moving_foreground = CellGrid::new(w, h, cell_px);
    let mut confirmed_foreground = CellGrid::new(w, h, cell_px);
    for (i, &label) in labels.iter().enumerate() {
        table.prefetch_ahead(&prev.x, &prev.y, i);
        let Some([x, y]) = table.get(prev.x[i], prev.y[i]) else {
            continue;
        };
        let (x, y) = (f64::from(x), f64::from(y));
        let mut f = model.map_or([0.0, 0.0], |a| planar_flow(x, y, &a));
        if let Some(wr) = prev.omega {
            let r = rotational_flow(x, y, wr);
            f = [f[0] + r[0], f[1] + r[1]];
        }
        let [u, v] = camera.normalized_to_pixel(x + f[0] * dt, y + f[1] * dt);
        let grid = if label == 0 {
            &mut background
        } else {
            &mut foreground
        };
        if let Some(c) = grid.cell_f(u + 0.5, v + 0.5) {
            grid.values[c] += 1.0;
            if label != 0 && prev.moving.get(i).is_some_and(|&m| m) {
                moving_foreground.values[c] += 1.0;
            }
            if label != 0 && prev.confirmed.get(i).is_some_and(|&m| m) {
                confirmed_foreground.values[c] += 1.0;
            }
        }
    }
    Some(WarpedPrevious {
        background: background.dilated(),
        foreground: foreground.dilated(),
        moving_foreground: moving_foreground.dilated(),
        confirmed_foreground: confirmed_foreground.dilated(),
        model,
    })
}
