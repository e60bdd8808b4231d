//! Rigid-body helpers on plain arrays, shared by the simulator and the evaluator: 3-vectors,
//! rotation matrices (row-major `[[f64; 3]; 3]`), unit quaternions `[x, y, z, w]` (the schemas'
//! order), slerp and the SO(3) / SE(3) logarithms. Frames are the caller's: a matrix `r_ab`
//! maps coordinates in frame `b` to frame `a` (`mul_mv`), its transpose back (`mul_mtv`).
//! Small enough to inline across crates (the simulator's bounds call them per render step).

/// A 3-vector.
pub type Vec3 = [f64; 3];
/// A 3x3 matrix, row-major: `m[row][col]`.
pub type Mat3 = [[f64; 3]; 3];
/// A quaternion `[x, y, z, w]` (the schemas' order).
pub type Quat = [f64; 4];

/// The identity matrix.
pub const IDENTITY: Mat3 = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]];

/// `a + b`.
#[inline]
pub fn add(a: Vec3, b: Vec3) -> Vec3 {
    [a[0] + b[0], a[1] + b[1], a[2] + b[2]]
}

/// `a - b`.
#[inline]
pub fn sub(a: Vec3, b: Vec3) -> Vec3 {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}

/// `s * a`.
#[inline]
pub fn scale(a: Vec3, s: f64) -> Vec3 {
    [a[0] * s, a[1] * s, a[2] * s]
}

/// Dot product.
#[inline]
pub fn dot(a: Vec3, b: Vec3) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

/// Cross product `a x b`.
#[inline]
pub fn cross(a: Vec3, b: Vec3) -> Vec3 {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}

/// Euclidean norm.
#[inline]
pub fn norm(a: Vec3) -> f64 {
    dot(a, a).sqrt()
}

/// `a / |a|` (returns `a` unchanged when it is zero).
#[inline]
pub fn normalize(a: Vec3) -> Vec3 {
    let n = norm(a);
    if n > 0.0 { scale(a, 1.0 / n) } else { a }
}

/// Linear interpolation `a + s (b - a)`.
#[inline]
pub fn lerp(a: Vec3, b: Vec3, s: f64) -> Vec3 {
    add(a, scale(sub(b, a), s))
}

/// Angle between two vectors, radians in `[0, pi]` (meaningless, 0, if either is zero: callers
/// check norms first).
#[inline]
pub fn angle_between(a: Vec3, b: Vec3) -> f64 {
    // atan2 of |a x b| and a.b is accurate at small and large angles alike.
    norm(cross(a, b)).atan2(dot(a, b))
}

/// `m v`.
#[inline]
pub fn mul_mv(m: &Mat3, v: Vec3) -> Vec3 {
    [dot(m[0], v), dot(m[1], v), dot(m[2], v)]
}

/// `m^T v`.
#[inline]
pub fn mul_mtv(m: &Mat3, v: Vec3) -> Vec3 {
    [
        m[0][0] * v[0] + m[1][0] * v[1] + m[2][0] * v[2],
        m[0][1] * v[0] + m[1][1] * v[1] + m[2][1] * v[2],
        m[0][2] * v[0] + m[1][2] * v[1] + m[2][2] * v[2],
    ]
}

/// `a b`.
#[inline]
pub fn mul_mm(a: &Mat3, b: &Mat3) -> Mat3 {
    let mut r = [[0.0; 3]; 3];
    for (i, row) in r.iter_mut().enumerate() {
        for (j, cell) in row.iter_mut().enumerate() {
            *cell = a[i][0] * b[0][j] + a[i][1] * b[1][j] + a[i][2] * b[2][j];
        }
    }
    r
}

/// `m^T`.
#[inline]
pub fn transpose(m: &Mat3) -> Mat3 {
    [
        [m[0][0], m[1][0], m[2][0]],
        [m[0][1], m[1][1], m[2][1]],
        [m[0][2], m[1][2], m[2][2]],
    ]
}

/// Column `j` of `m`.
#[inline]
pub fn column(m: &Mat3, j: usize) -> Vec3 {
    [m[0][j], m[1][j], m[2][j]]
}

/// Rotation by `angle` (rad) about the unit axis `axis` (0 = x, 1 = y, 2 = z), right-handed.
pub fn rot_axis(axis: usize, angle: f64) -> Mat3 {
    let (s, c) = angle.sin_cos();
    match axis {
        0 => [[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]],
        1 => [[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]],
        _ => [[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]],
    }
}

/// The unit quaternion of `q`, or `None` when its norm is zero or not finite.
pub fn quat_normalize(q: Quat) -> Option<Quat> {
    let n = (q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3]).sqrt();
    (n.is_finite() && n > 0.0).then(|| [q[0] / n, q[1] / n, q[2] / n, q[3] / n])
}

/// Rotation matrix of a unit quaternion `[x, y, z, w]`.
pub fn quat_to_mat(q: Quat) -> Mat3 {
    let [x, y, z, w] = q;
    [
        [
            1.0 - 2.0 * (y * y + z * z),
            2.0 * (x * y - z * w),
            2.0 * (x * z + y * w),
        ],
        [
            2.0 * (x * y + z * w),
            1.0 - 2.0 * (x * x + z * z),
            2.0 * (y * z - x * w),
        ],
        [
            2.0 * (x * z - y * w),
            2.0 * (y * z + x * w),
            1.0 - 2.0 * (x * x + y * y),
        ],
    ]
}

/// Unit quaternion `[x, y, z, w]` (w >= 0) of a rotation matrix.
pub fn quat_from_mat(m: &Mat3) -> Quat {
    let tr = m[0][0] + m[1][1] + m[2][2];
    let q = if tr > 0.0 {
        let s = (tr + 1.0).sqrt() * 2.0;
        [
            (m[2][1] - m[1][2]) / s,
            (m[0][2] - m[2][0]) / s,
            (m[1][0] - m[0][1]) / s,
            0.25 * s,
        ]
    } else if m[0][0] > m[1][1] && m[0][0] > m[2][2] {
        let s = (1.0 + m[0][0] - m[1][1] - m[2][2]).sqrt() * 2.0;
        [
            0.25 * s,
            (m[0][1] + m[1][0]) / s,
            (m[0][2] + m[2][0]) / s,
            (m[2][1] - m[1][2]) / s,
        ]
    } else if m[1][1] > m[2][2] {
        let s = (1.0 + m[1][1] - m[0][0] - m[2][2]).sqrt() * 2.0;
        [
            (m[0][1] + m[1][0]) / s,
            0.25 * s,
            (m[1][2] + m[2][1]) / s,
            (m[0][2] - m[2][0]) / s,
        ]
    } else {
        let s = (1.0 + m[2][2] - m[0][0] - m[1][1]).sqrt() * 2.0;
        [
            (m[0][2] + m[2][0]) / s,
            (m[1][2] + m[2][1]) / s,
            0.25 * s,
            (m[1][0] - m[0][1]) / s,
        ]
    };
    let n = (q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3]).sqrt();
    let sign = if q[3] < 0.0 { -1.0 } else { 1.0 };
    [sign * q[0] / n, sign * q[1] / n, sign * q[2] / n, sign * q[3] / n]
}

/// Quaternion `[x, y, z, w]` of a rotation by `angle` radians about the unit `axis`.
pub fn quat_from_axis_angle(axis: Vec3, angle: f64) -> Quat {
    let (s, c) = (angle / 2.0).sin_cos();
    [axis[0] * s, axis[1] * s, axis[2] * s, c]
}

/// Spherical linear interpolation between unit quaternions, `s` in `[0, 1]`, along the shorter
/// arc (q and -q are the same rotation).
pub fn slerp(a: Quat, b: Quat, s: f64) -> Quat {
    let mut d = a[0] * b[0] + a[1] * b[1] + a[2] * b[2] + a[3] * b[3];
    let b = if d < 0.0 {
        d = -d;
        [-b[0], -b[1], -b[2], -b[3]]
    } else {
        b
    };
    // Nearly parallel: the sine below vanishes; normalized lerp is exact to rounding there.
    let (wa, wb) = if d > 1.0 - 1e-12 {
        (1.0 - s, s)
    } else {
        let theta = d.min(1.0).acos();
        let sin = theta.sin();
        (((1.0 - s) * theta).sin() / sin, (s * theta).sin() / sin)
    };
    let q = [
        wa * a[0] + wb * b[0],
        wa * a[1] + wb * b[1],
        wa * a[2] + wb * b[2],
        wa * a[3] + wb * b[3],
    ];
    quat_normalize(q).unwrap_or(a)
}

/// SO(3) logarithm: the rotation vector (axis times angle, radians) of a rotation matrix.
pub fn so3_log(r: &Mat3) -> Vec3 {
    let cos = ((r[0][0] + r[1][1] + r[2][2] - 1.0) / 2.0).clamp(-1.0, 1.0);
    let angle = cos.acos();
    let v = [r[2][1] - r[1][2], r[0][2] - r[2][0], r[1][0] - r[0][1]];
    if angle < 1e-6 {
        // First order: R ~ I + [phi]x.
        return scale(v, 0.5);
    }
    if std::f64::consts::PI - angle < 1e-6 {
        // Near pi the antisymmetric part vanishes: the axis is the column of R + I of largest norm.
        let cols = [0, 1, 2].map(|c| {
            [
                r[0][c] + (c == 0) as u8 as f64,
                r[1][c] + (c == 1) as u8 as f64,
                r[2][c] + (c == 2) as u8 as f64,
            ]
        });
        let best = cols
            .iter()
            .copied()
            .max_by(|a, b| norm(*a).total_cmp(&norm(*b)))
            .unwrap_or([1.0, 0.0, 0.0]);
        return scale(best, angle / norm(best));
    }
    scale(v, angle / (2.0 * angle.sin()))
}

/// SE(3) logarithm of the transform `p -> R p + t`: the twist `(rho, phi)` with `phi` the rotation
/// vector and `rho = V(phi)^-1 t`, so that the constant-twist motion `dP/ds = rho + phi x P`
/// for `s` from 0 to 1 maps every point `P` to `R P + t`.
pub fn se3_log(r: &Mat3, t: Vec3) -> (Vec3, Vec3) {
    let phi = so3_log(r);
    let theta = norm(phi);
    // V^-1 = I - 1/2 [phi]x + c [phi]x^2 with c = (1 - theta sin / (2 (1 - cos))) / theta^2.
    let c = if theta < 1e-4 {
        1.0 / 12.0 + theta * theta / 720.0
    } else {
        (1.0 - theta * theta.sin() / (2.0 * (1.0 - theta.cos()))) / (theta * theta)
    };
    let pxt = cross(phi, t);
    let pxpxt = cross(phi, pxt);
    let rho = add(sub(t, scale(pxt, 0.5)), scale(pxpxt, c));
    (rho, phi)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn close(a: Vec3, b: Vec3, tol: f64) -> bool {
        norm(sub(a, b)) < tol
    }

    #[test]
    fn quaternion_rotates_x_to_y_about_z() {
        let q = quat_from_axis_angle([0.0, 0.0, 1.0], std::f64::consts::FRAC_PI_2);
        let m = quat_to_mat(q);
        assert!(close(mul_mv(&m, [1.0, 0.0, 0.0]), [0.0, 1.0, 0.0], 1e-12));
        assert!(close(mul_mtv(&m, [0.0, 1.0, 0.0]), [1.0, 0.0, 0.0], 1e-12));
    }

    #[test]
    fn slerp_halfway_is_half_the_angle_and_takes_the_short_arc() {
        let a = quat_from_axis_angle([0.0, 1.0, 0.0], 0.2);
        let b = quat_from_axis_angle([0.0, 1.0, 0.0], 1.0);
        let mid = slerp(a, b, 0.5);
        let want = quat_from_axis_angle([0.0, 1.0, 0.0], 0.6);
        assert!((0..4).all(|i| (mid[i] - want[i]).abs() < 1e-12), "{mid:?}");
        let neg_b = [-b[0], -b[1], -b[2], -b[3]];
        let mid2 = slerp(a, neg_b, 0.5);
        assert!(close(so3_log(&quat_to_mat(mid2)), [0.0, 0.6, 0.0], 1e-12));
    }

    #[test]
    fn so3_log_inverts_axis_angle_including_near_pi() {
        for angle in [0.0, 1e-8, 0.3, 2.0, std::f64::consts::PI - 1e-9] {
            let axis = [2.0_f64, -1.0, 0.5];
            let axis = scale(axis, 1.0 / norm(axis));
            let phi = so3_log(&quat_to_mat(quat_from_axis_angle(axis, angle)));
            assert!(close(phi, scale(axis, angle), 1e-6), "angle {angle}: {phi:?}");
        }
    }

    #[test]
    fn se3_log_of_screw_motion_recovers_the_twist() {
        // Integrate dP/ds = rho + phi x P from a point, compare with R P + t from the log.
        let rho = [0.3, -0.2, 0.5];
        let phi = [0.1, 0.4, -0.2];
        let r = quat_to_mat(quat_from_axis_angle(scale(phi, 1.0 / norm(phi)), norm(phi)));
        // Translation of the exponential: t = V rho, built by integrating the origin's path.
        let mut p = [0.0; 3];
        let n = 20000;
        for _ in 0..n {
            let k = |q: Vec3| add(rho, cross(phi, q));
            let h = 1.0 / n as f64;
            let k1 = k(p);
            let k2 = k(add(p, scale(k1, h / 2.0)));
            let k3 = k(add(p, scale(k2, h / 2.0)));
            let k4 = k(add(p, scale(k3, h)));
            p = add(
                p,
                scale(add(add(k1, scale(k2, 2.0)), add(scale(k3, 2.0), k4)), h / 6.0),
            );
        }
        let (rho2, phi2) = se3_log(&r, p);
        assert!(close(phi2, phi, 1e-9), "{phi2:?}");
        assert!(close(rho2, rho, 1e-9), "{rho2:?}");
    }

    #[test]
    fn angle_between_known_vectors() {
        let a = angle_between([1.0, 0.0, 0.0], [1.0, 1.0, 0.0]);
        assert!((a.to_degrees() - 45.0).abs() < 1e-12);
        let b = angle_between([0.0, 0.0, 2.0], [0.0, 0.0, -1.0]);
        assert!((b - std::f64::consts::PI).abs() < 1e-12);
    }

    #[test]
    fn quaternion_of_axis_rotation() {
        let q = quat_from_mat(&rot_axis(2, 0.5));
        assert!((q[2] - (0.25f64).sin()).abs() < 1e-12);
        assert!((q[3] - (0.25f64).cos()).abs() < 1e-12);
        let q = quat_from_mat(&rot_axis(0, 3.0));
        assert!((q[0] - (1.5f64).sin()).abs() < 1e-12, "{q:?}");
    }

    #[test]
    fn rotation_composition_is_orthonormal() {
        let r = mul_mm(&rot_axis(0, 0.3), &rot_axis(1, -1.2));
        let p = mul_mm(&r, &transpose(&r));
        for (i, row) in p.iter().enumerate() {
            for (j, v) in row.iter().enumerate() {
                assert!((v - if i == j { 1.0 } else { 0.0 }).abs() < 1e-12);
            }
        }
        assert!((cross([1.0, 0.0, 0.0], [0.0, 1.0, 0.0])[2] - 1.0).abs() < 1e-15);
    }
}
