//! Pinhole camera with optional radial-tangential distortion, and the per-pixel viewing rays.
//!
//! The event pixel grid is the *distorted* image: pixel `(u, v)` sees the ray through the
//! undistorted normalized point `undistort((u - cx) / fx, (v - cy) / fy)`.

use evseg_schemas::Distortion;
use serde::{Deserialize, Serialize};

use crate::SimError;

/// Intrinsics and lens of the simulated camera.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct CameraConfig {
    /// Sensor width, pixels.
    pub width: u16,
    /// Sensor height, pixels.
    pub height: u16,
    /// Focal length x, pixels.
    pub fx: f64,
    /// Focal length y, pixels.
    pub fy: f64,
    /// Principal point x, pixels.
    pub cx: f64,
    /// Principal point y, pixels.
    pub cy: f64,
    /// Lens distortion (`None` or `RadTan`; `Equidistant` is rejected).
    pub distortion: Distortion,
}

impl CameraConfig {
    /// Checks the values; errors name the offending field.
    pub fn validate(&self) -> Result<(), SimError> {
        if self.width < 8 || self.height < 8 {
            return Err(SimError::Config(format!(
                "camera size {}x{} too small (at least 8x8)",
                self.width, self.height
            )));
        }
        for (name, v) in [("fx", self.fx), ("fy", self.fy)] {
            if !(v.is_finite() && v > 1.0) {
                return Err(SimError::Config(format!(
                    "camera.{name} = {v} must be a finite value > 1 px"
                )));
            }
        }
        for (name, v) in [("cx", self.cx), ("cy", self.cy)] {
            if !v.is_finite() {
                return Err(SimError::Config(format!("camera.{name} = {v} is not finite")));
            }
        }
        match self.distortion {
            Distortion::None => Ok(()),
            Distortion::RadTan { k1, k2, p1, p2, k3 } => {
                if [k1, k2, p1, p2, k3]
                    .iter()
                    .any(|v| !v.is_finite() || v.abs() > 2.0)
                {
                    return Err(SimError::Config(
                        "camera.distortion coefficients must be finite, |k| <= 2".into(),
                    ));
                }
                Ok(())
            }
            Distortion::Equidistant { .. } => Err(SimError::Config(
                "camera.distortion: Equidistant is not supported by the simulator (use None or RadTan)"
                    .into(),
            )),
        }
    }

    /// Distorts an undistorted normalized point (identity without distortion).
    pub fn distort(&self, x: f64, y: f64) -> (f64, f64) {
        match self.distortion {
            Distortion::RadTan { k1, k2, p1, p2, k3 } => {
                let r2 = x * x + y * y;
                let radial = 1.0 + r2 * (k1 + r2 * (k2 + r2 * k3));
                (
                    x * radial + 2.0 * p1 * x * y + p2 * (r2 + 2.0 * x * x),
                    y * radial + p1 * (r2 + 2.0 * y * y) + 2.0 * p2 * x * y,
                )
            }
            _ => (x, y),
        }
    }

    /// Jacobian `d(distorted) / d(undistorted)` at an undistorted normalized point, row-major 2x2.
    pub fn distortion_jacobian(&self, x: f64, y: f64) -> [f64; 4] {
        match self.distortion {
            Distortion::RadTan { k1, k2, p1, p2, k3 } => {
                let r2 = x * x + y * y;
                let radial = 1.0 + r2 * (k1 + r2 * (k2 + r2 * k3));
                let dr = k1 + 2.0 * k2 * r2 + 3.0 * k3 * r2 * r2; // d radial / d r2
                [
                    radial + 2.0 * x * x * dr + 2.0 * p1 * y + 6.0 * p2 * x,
                    2.0 * x * y * dr + 2.0 * p1 * x + 2.0 * p2 * y,
                    2.0 * x * y * dr + 2.0 * p1 * x + 2.0 * p2 * y,
                    radial + 2.0 * y * y * dr + 6.0 * p1 * y + 2.0 * p2 * x,
                ]
            }
            _ => [1.0, 0.0, 0.0, 1.0],
        }
    }

    /// Undistorts a distorted normalized point by Newton iteration.
    pub fn undistort(&self, xd: f64, yd: f64) -> (f64, f64) {
        if matches!(self.distortion, Distortion::None) {
            return (xd, yd);
        }
        let (mut x, mut y) = (xd, yd);
        for _ in 0..20 {
            let (fx, fy) = self.distort(x, y);
            let (ex, ey) = (fx - xd, fy - yd);
            if ex.abs() + ey.abs() < 1e-14 {
                break;
            }
            let j = self.distortion_jacobian(x, y);
            let det = j[0] * j[3] - j[1] * j[2];
            if det.abs() < 1e-12 {
                break;
            }
            x -= (j[3] * ex - j[1] * ey) / det;
            y -= (-j[2] * ex + j[0] * ey) / det;
        }
        (x, y)
    }

    /// Pixel position of a camera-frame point (None behind the camera).
    pub fn project(&self, p: [f64; 3]) -> Option<(f64, f64)> {
        if p[2] <= 1e-9 {
            return None;
        }
        let (xd, yd) = self.distort(p[0] / p[2], p[1] / p[2]);
        Some((self.fx * xd + self.cx, self.fy * yd + self.cy))
    }

    /// Pixel flow (px/s) of a normalized flow `(ux, uy)` (1/s) at undistorted normalized `(x, y)`.
    pub fn pixel_flow(&self, x: f64, y: f64, ux: f64, uy: f64) -> (f64, f64) {
        let j = self.distortion_jacobian(x, y);
        (
            self.fx * (j[0] * ux + j[1] * uy),
            self.fy * (j[2] * ux + j[3] * uy),
        )
    }
}

/// The viewing ray of every pixel, `d = (x, y, 1)` in the camera frame with `(x, y)` the
/// undistorted normalized coordinates, plus the ray change per pixel for sub-pixel samples.
#[derive(Debug, Clone)]
pub struct Rays {
    /// Width, pixels.
    pub width: usize,
    /// Height, pixels.
    pub height: usize,
    /// Normalized x of each pixel centre, row-major.
    pub x: Vec<f32>,
    /// Normalized y of each pixel centre, row-major.
    pub y: Vec<f32>,
    /// `d(x, y) / du` (per pixel along the row), row-major pairs.
    pub d_du: Vec<[f32; 2]>,
    /// `d(x, y) / dv` (per pixel down the column), row-major pairs.
    pub d_dv: Vec<[f32; 2]>,
    /// Largest |x| over the image, normalized units.
    pub max_abs_x: f64,
    /// Largest |y| over the image, normalized units.
    pub max_abs_y: f64,
    /// Largest Frobenius norm of the distortion Jacobian over the image (1 without distortion).
    pub max_jacobian: f64,
}

impl Rays {
    /// Computes the rays of `cam`.
    pub fn new(cam: &CameraConfig) -> Self {
        let (w, h) = (cam.width as usize, cam.height as usize);
        let n = w * h;
        let mut rays = Rays {
            width: w,
            height: h,
            x: vec![0.0; n],
            y: vec![0.0; n],
            d_du: vec![[0.0; 2]; n],
            d_dv: vec![[0.0; 2]; n],
            max_abs_x: 0.0,
            max_abs_y: 0.0,
            max_jacobian: 1.0,
        };
        for v in 0..h {
            for u in 0..w {
                let i = v * w + u;
                let (x, y) = cam.undistort((u as f64 - cam.cx) / cam.fx, (v as f64 - cam.cy) / cam.fy);
                rays.x[i] = x as f32;
                rays.y[i] = y as f32;
                let j = cam.distortion_jacobian(x, y);
                let det = j[0] * j[3] - j[1] * j[2];
                // Inverse Jacobian times d(distorted)/d(pixel) = diag(1/fx, 1/fy).
                let inv = [j[3] / det, -j[1] / det, -j[2] / det, j[0] / det];
                rays.d_du[i] = [(inv[0] / cam.fx) as f32, (inv[2] / cam.fx) as f32];
                rays.d_dv[i] = [(inv[1] / cam.fy) as f32, (inv[3] / cam.fy) as f32];
                rays.max_abs_x = rays.max_abs_x.max(x.abs());
                rays.max_abs_y = rays.max_abs_y.max(y.abs());
                let fro = (j.iter().map(|a| a * a).sum::<f64>() / 2.0).sqrt();
                rays.max_jacobian = rays.max_jacobian.max(fro);
            }
        }
        rays
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn cam(d: Distortion) -> CameraConfig {
        CameraConfig {
            width: 64,
            height: 48,
            fx: 50.0,
            fy: 52.0,
            cx: 31.5,
            cy: 23.5,
            distortion: d,
        }
    }

    #[test]
    fn undistort_inverts_distort_and_jacobian_matches() {
        let c = cam(Distortion::RadTan {
            k1: -0.2,
            k2: 0.05,
            p1: 0.001,
            p2: -0.002,
            k3: 0.0,
        });
        for &(x, y) in &[(0.3, -0.2), (-0.5, 0.4), (0.0, 0.0)] {
            let (xd, yd) = c.distort(x, y);
            let (xu, yu) = c.undistort(xd, yd);
            assert!((xu - x).abs() < 1e-10 && (yu - y).abs() < 1e-10);
            let h = 1e-6;
            let j = c.distortion_jacobian(x, y);
            let (a, b) = c.distort(x + h, y);
            let (a0, b0) = c.distort(x - h, y);
            assert!(((a - a0) / (2.0 * h) - j[0]).abs() < 1e-6);
            assert!(((b - b0) / (2.0 * h) - j[2]).abs() < 1e-6);
        }
    }

    #[test]
    fn rays_project_back_to_their_pixels() {
        let c = cam(Distortion::RadTan {
            k1: -0.15,
            k2: 0.02,
            p1: 0.0,
            p2: 0.001,
            k3: 0.0,
        });
        let r = Rays::new(&c);
        for &(u, v) in &[(0usize, 0usize), (63, 47), (10, 30)] {
            let i = v * 64 + u;
            let (pu, pv) = c
                .project([r.x[i] as f64 * 2.0, r.y[i] as f64 * 2.0, 2.0])
                .unwrap();
            assert!(
                (pu - u as f64).abs() < 1e-3 && (pv - v as f64).abs() < 1e-3,
                "{pu} {pv}"
            );
        }
        let plain = Rays::new(&cam(Distortion::None));
        assert!((plain.d_du[5][0] - 1.0 / 50.0).abs() < 1e-7);
        assert_eq!(plain.max_jacobian, 1.0);
        assert!(
            cam(Distortion::Equidistant {
                k1: 0.0,
                k2: 0.0,
                k3: 0.0,
                k4: 0.0
            })
            .validate()
            .is_err()
        );
    }
}
