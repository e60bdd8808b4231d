//! Motion-field matrices (METHOD_NOTES section 1, the paper's equations 1-5).
//!
//! `u(x) = (1/Z) A(x) t + B(x) w`, and for a planar scene `u(x) = C(x) a` with the 8 homography
//! flow parameters `a`. `x = (x, y)` in normalized coordinates.

/// `A(x) = [[-1, 0, x], [0, -1, y]]`: flow per unit translation at unit depth.
pub fn a_matrix(x: f64, y: f64) -> [[f64; 3]; 2] {
    [[-1.0, 0.0, x], [0.0, -1.0, y]]
}

/// `B(x) = [[x y, -(1 + x^2), y], [1 + y^2, -x y, -x]]`: flow per unit rotation rate.
pub fn b_matrix(x: f64, y: f64) -> [[f64; 3]; 2] {
    [[x * y, -(1.0 + x * x), y], [1.0 + y * y, -x * y, -x]]
}

/// `C(x) = [[x^2, x y, x, y, 1, 0, 0, 0], [x y, y^2, 0, 0, 0, y, x, 1]]`: planar-scene flow.
pub fn c_matrix(x: f64, y: f64) -> [[f64; 8]; 2] {
    [
        [x * x, x * y, x, y, 1.0, 0.0, 0.0, 0.0],
        [x * y, y * y, 0.0, 0.0, 0.0, y, x, 1.0],
    ]
}

fn mul<const N: usize>(m: &[[f64; N]; 2], v: &[f64; N]) -> [f64; 2] {
    let mut out = [0.0; 2];
    for (o, row) in out.iter_mut().zip(m) {
        *o = row.iter().zip(v).map(|(a, b)| a * b).sum();
    }
    out
}

/// Flow of rotation rate `w` (rad/s, camera frame) at `(x, y)`: `B(x) w`, normalized units/s.
pub fn rotational_flow(x: f64, y: f64, w: [f64; 3]) -> [f64; 2] {
    mul(&b_matrix(x, y), &w)
}

/// Flow of translation `t` at inverse depth `inv_z`: `inv_z A(x) t`, normalized units/s.
pub fn translational_flow(x: f64, y: f64, t: [f64; 3], inv_z: f64) -> [f64; 2] {
    let f = mul(&a_matrix(x, y), &t);
    [f[0] * inv_z, f[1] * inv_z]
}

/// Planar-scene flow `C(x) a` at `(x, y)` for the 8 parameters `a`, normalized units/s.
pub fn planar_flow(x: f64, y: f64, a: &[f64; 8]) -> [f64; 2] {
    mul(&c_matrix(x, y), a)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A plane `1/Z = (alpha x + beta y + gamma) / d` seen by a camera moving with (t, w) has the
    /// flow `C(x) a` with `a` from the paper's equation (one sign corrected, see below); this
    /// checks `C` against `A` and `B`.
    #[test]
    fn planar_flow_matches_the_motion_field_of_a_plane() {
        let (t, w) = ([0.3, -0.2, 0.5], [0.05, -0.1, 0.2]);
        let (alpha, beta, gamma, d) = (0.1, -0.2, 1.0, 2.0);
        let a = [
            -d * w[1] + t[2] * alpha,
            d * w[0] + t[2] * beta,
            t[2] * gamma - t[0] * alpha,
            // The paper prints `d wz + tx beta`; expanding (1/Z) A t + B w gives `- tx beta`
            // (the y coefficient of u_x is -tx beta / d + wz), which is what this checks.
            d * w[2] - t[0] * beta,
            -d * w[1] - t[0] * gamma,
            t[2] * gamma - t[1] * beta,
            -d * w[2] - t[1] * alpha,
            d * w[0] - t[1] * gamma,
        ];
        // The paper's a is for d * u; divide by d.
        let a: Vec<f64> = a.iter().map(|v| v / d).collect();
        let a: [f64; 8] = a.try_into().unwrap();
        for &(x, y) in &[(0.0, 0.0), (0.3, -0.2), (-0.4, 0.25)] {
            let inv_z = (alpha * x + beta * y + gamma) / d;
            let tr = translational_flow(x, y, t, inv_z);
            let ro = rotational_flow(x, y, w);
            let p = planar_flow(x, y, &a);
            assert!(
                (p[0] - (tr[0] + ro[0])).abs() < 1e-12,
                "{p:?} vs {:?}",
                [tr[0] + ro[0], tr[1] + ro[1]]
            );
            assert!((p[1] - (tr[1] + ro[1])).abs() < 1e-12);
        }
    }

    #[test]
    fn rotation_about_the_optical_axis_turns_points_around_the_centre() {
        let f = rotational_flow(1.0, 0.0, [0.0, 0.0, 1.0]);
        assert_eq!(f, [0.0, -1.0]);
    }
}
