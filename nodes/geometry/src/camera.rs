//! The camera model: pixels <-> normalized coordinates through the lens distortion.

use evseg_schemas::align::AlignError;
use evseg_schemas::{CameraInfo, Distortion};

/// Iterations of the fixed-point undistortion (converges to ~1e-12 for the lenses of EVIMO2 and
/// the simulator within 20; the loop also stops early when the step is below 1e-14).
pub const UNDISTORT_ITERATIONS: usize = 40;

/// A calibrated camera.
#[derive(Debug, Clone, PartialEq)]
pub struct Camera {
    /// The calibration it was built from.
    pub info: CameraInfo,
}

impl Camera {
    /// A camera from its calibration.
    pub fn new(info: &CameraInfo) -> Self {
        Self { info: info.clone() }
    }

    /// Applies the lens distortion to undistorted normalized coordinates.
    pub fn distort(&self, x: f64, y: f64) -> [f64; 2] {
        match self.info.distortion {
            Distortion::None => [x, y],
            Distortion::RadTan { k1, k2, p1, p2, k3 } => {
                let r2 = x * x + y * y;
                let radial = 1.0 + r2 * (k1 + r2 * (k2 + r2 * k3));
                [
                    x * radial + 2.0 * p1 * x * y + p2 * (r2 + 2.0 * x * x),
                    y * radial + p1 * (r2 + 2.0 * y * y) + 2.0 * p2 * x * y,
                ]
            }
            Distortion::Equidistant { k1, k2, k3, k4 } => {
                let r = (x * x + y * y).sqrt();
                if r < 1e-12 {
                    return [x, y];
                }
                let th = r.atan();
                let th2 = th * th;
                let thd = th * (1.0 + th2 * (k1 + th2 * (k2 + th2 * (k3 + th2 * k4))));
                [x * thd / r, y * thd / r]
            }
        }
    }

    /// Removes the lens distortion from distorted normalized coordinates (iterative inverse).
    pub fn undistort(&self, xd: f64, yd: f64) -> [f64; 2] {
        if matches!(self.info.distortion, Distortion::None) {
            return [xd, yd];
        }
        let (mut x, mut y) = (xd, yd);
        for _ in 0..UNDISTORT_ITERATIONS {
            let [dx, dy] = self.distort(x, y);
            let (ex, ey) = (xd - dx, yd - dy);
            x += ex;
            y += ey;
            if ex.abs() + ey.abs() < 1e-14 {
                break;
            }
        }
        [x, y]
    }

    /// Pixel coordinates to undistorted normalized coordinates.
    pub fn pixel_to_normalized(&self, u: f64, v: f64) -> [f64; 2] {
        let i = &self.info;
        self.undistort((u - i.cx) / i.fx, (v - i.cy) / i.fy)
    }

    /// Undistorted normalized coordinates to pixel coordinates.
    pub fn normalized_to_pixel(&self, x: f64, y: f64) -> [f64; 2] {
        let [xd, yd] = self.distort(x, y);
        let i = &self.info;
        [xd * i.fx + i.cx, yd * i.fy + i.cy]
    }

    /// Converts a flow vector at pixel `(u, v)` from pixels/s to normalized units/s, through the
    /// local Jacobian of the undistortion (central differences of half a pixel).
    pub fn pixel_flow_to_normalized(&self, u: f64, v: f64, fu: f64, fv: f64) -> [f64; 2] {
        let h = 0.5;
        let [xp, yp] = self.pixel_to_normalized(u + h, v);
        let [xm, ym] = self.pixel_to_normalized(u - h, v);
        let [xq, yq] = self.pixel_to_normalized(u, v + h);
        let [xn, yn] = self.pixel_to_normalized(u, v - h);
        let (j00, j10) = ((xp - xm) / (2.0 * h), (yp - ym) / (2.0 * h));
        let (j01, j11) = ((xq - xn) / (2.0 * h), (yq - yn) / (2.0 * h));
        [j00 * fu + j01 * fv, j10 * fu + j11 * fv]
    }

    /// A per-pixel table of normalized coordinates, for hot loops over events.
    pub fn undistort_table(&self) -> UndistortTable {
        let (w, h) = (self.info.width as usize, self.info.height as usize);
        let mut xy = Vec::with_capacity(w * h);
        for v in 0..h {
            for u in 0..w {
                let [x, y] = self.pixel_to_normalized(u as f64, v as f64);
                xy.push([x as f32, y as f32]);
            }
        }
        UndistortTable {
            width: self.info.width,
            height: self.info.height,
            xy,
        }
    }
}

/// Undistorted normalized coordinates of every pixel centre, row-major.
#[derive(Debug, Clone, PartialEq)]
pub struct UndistortTable {
    /// Width, pixels.
    pub width: u16,
    /// Height, pixels.
    pub height: u16,
    /// `[x, y]` normalized, per pixel.
    pub xy: Vec<[f32; 2]>,
}

impl UndistortTable {
    /// Normalized coordinates of pixel `(u, v)`; `None` outside the sensor.
    pub fn get(&self, u: u16, v: u16) -> Option<[f32; 2]> {
        if u >= self.width || v >= self.height {
            return None;
        }
        self.xy
            .get(v as usize * self.width as usize + u as usize)
            .copied()
    }

    /// Asks the cache for the entry of pixel `(u, v)` (nothing outside the sensor), for a
    /// lookup a few events later ([`crate::cache`]).
    #[inline]
    pub fn prefetch(&self, u: u16, v: u16) {
        if u < self.width
            && v < self.height
            && let Some(e) = self.xy.get(v as usize * self.width as usize + u as usize)
        {
            crate::cache::prefetch(e);
        }
    }

    /// Asks the cache for the entry of event `index + PREFETCH_AHEAD` of `events`' pixels `x`,
    /// `y` (nothing past the end), for the lookup of that event a few events later.
    #[inline]
    pub fn prefetch_ahead(&self, x: &[u16], y: &[u16], index: usize) {
        let ahead = index + crate::cache::PREFETCH_AHEAD;
        if let (Some(&u), Some(&v)) = (x.get(ahead), y.get(ahead)) {
            self.prefetch(u, v);
        }
    }

    /// Normalized coordinates of event `index` at pixel `(u, v)`; an event outside the sensor
    /// is an error naming it.
    pub fn event(&self, index: usize, u: u16, v: u16) -> Result<[f32; 2], AlignError> {
        self.get(u, v).ok_or(AlignError::EventOutside {
            index,
            x: u,
            y: v,
            width: self.width,
            height: self.height,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn info(distortion: Distortion) -> CameraInfo {
        CameraInfo {
            distortion,
            ..CameraInfo::pinhole(640, 480, 500.0, "t")
        }
    }

    #[test]
    fn undistort_inverts_distort() {
        for d in [
            Distortion::None,
            Distortion::RadTan {
                k1: -0.3,
                k2: 0.1,
                p1: 0.001,
                p2: -0.002,
                k3: 0.0,
            },
            Distortion::Equidistant {
                k1: 0.05,
                k2: -0.01,
                k3: 0.002,
                k4: 0.0,
            },
        ] {
            let cam = Camera::new(&info(d));
            for &(x, y) in &[(0.0, 0.0), (0.3, -0.2), (-0.5, 0.4)] {
                let [xd, yd] = cam.distort(x, y);
                let [xu, yu] = cam.undistort(xd, yd);
                assert!(
                    (xu - x).abs() < 1e-9 && (yu - y).abs() < 1e-9,
                    "{d:?}: {x},{y} -> {xu},{yu}"
                );
            }
            let [u, v] = cam.normalized_to_pixel(0.2, -0.1);
            let [x, y] = cam.pixel_to_normalized(u, v);
            assert!((x - 0.2).abs() < 1e-9 && (y + 0.1).abs() < 1e-9);
        }
    }

    #[test]
    fn pixel_flow_scales_by_focal_length_without_distortion() {
        let cam = Camera::new(&info(Distortion::None));
        let f = cam.pixel_flow_to_normalized(100.0, 50.0, 500.0, -250.0);
        assert!((f[0] - 1.0).abs() < 1e-12 && (f[1] + 0.5).abs() < 1e-12);
        let t = cam.undistort_table();
        assert_eq!(
            t.get(0, 0),
            Some([(-319.5f64 / 500.0) as f32, (-239.5f64 / 500.0) as f32])
        );
        assert_eq!(t.get(640, 0), None);
        let mut cache = TableCache::default();
        assert_eq!(cache.get(&cam.info).get(0, 0), t.get(0, 0));
        let other = CameraInfo::pinhole(4, 2, 1.0, "o");
        assert_eq!(cache.get(&other).width, 4, "a new camera rebuilds the table");
    }
}

/// The undistortion table of the last camera seen, rebuilt only when the camera changes (stages
/// get the calibration with every slice).
#[derive(Debug, Clone, Default)]
pub struct TableCache(Option<(CameraInfo, UndistortTable)>);

impl TableCache {
    /// The table for `camera`.
    pub fn get(&mut self, camera: &CameraInfo) -> &UndistortTable {
        if self.0.as_ref().is_some_and(|(c, _)| c != camera) {
            self.0 = None;
        }
        &self
            .0
            .get_or_insert_with(|| (camera.clone(), Camera::new(camera).undistort_table()))
            .1
    }
}
