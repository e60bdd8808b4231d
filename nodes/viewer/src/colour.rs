//! Colours: a stable palette per segment / track / object id, and the normal-flow direction
//! wheel. Pure functions returning `[r, g, b, a]` bytes (unmultiplied alpha).

/// Colour of label 0 (background): mid grey.
pub const BACKGROUND: [u8; 4] = [128, 128, 128, 255];
/// Colour of an event without a label (for example no valid flow): dark grey, half transparent.
pub const UNLABELLED: [u8; 4] = [60, 60, 60, 128];
/// Colour of an event without a normal-flow estimate (confidence 0): dark grey, half transparent.
pub const NO_FLOW: [u8; 4] = [60, 60, 60, 128];
/// Colour of an ON (brightness increase) event in the polarity layer.
pub const ON: [u8; 4] = [230, 90, 60, 255];
/// Colour of an OFF (brightness decrease) event in the polarity layer.
pub const OFF: [u8; 4] = [60, 130, 230, 255];

/// Golden-ratio conjugate: consecutive ids get hues as far apart as possible.
const GOLDEN: f64 = 0.618_033_988_749_894_8;

/// HSV (all in [0, 1]) to RGB bytes.
pub fn hsv(h: f64, s: f64, v: f64) -> [u8; 3] {
    let h = h.rem_euclid(1.0) * 6.0;
    let c = v * s;
    let x = c * (1.0 - ((h % 2.0) - 1.0).abs());
    let (r, g, b) = match h as u32 {
        0 => (c, x, 0.0),
        1 => (x, c, 0.0),
        2 => (0.0, c, x),
        3 => (0.0, x, c),
        4 => (x, 0.0, c),
        _ => (c, 0.0, x),
    };
    let m = v - c;
    let byte = |u: f64| ((u + m).clamp(0.0, 1.0) * 255.0).round() as u8;
    [byte(r), byte(g), byte(b)]
}

/// Colour of segment / track / object `id`: [`BACKGROUND`] for 0, [`UNLABELLED`] for
/// `u32::MAX` and `u16::MAX` (the pipeline's "no cluster" values, and a tracker's moving events
/// whose track is not confirmed yet, `Tracks::UNCONFIRMED`), else a saturated colour whose
/// hue is `id` times the golden-ratio conjugate (mod 1), so the same id has the same colour in
/// every slice, every layer and every run.
pub fn label_colour(id: u32) -> [u8; 4] {
    match id {
        0 => BACKGROUND,
        u32::MAX | 0xFFFF => UNLABELLED,
        _ => {
            let [r, g, b] = hsv(f64::from(id) * GOLDEN, 0.85, 0.95);
            [r, g, b, 255]
        }
    }
}

/// Colour of a normal-flow vector `(nx, ny)` (normalized image units per second, x right,
/// y down): hue = direction (0° = +x red, 90° = +y (down) yellow-green, ...), full saturation,
/// brightness 0.25 + 0.75 * min(1, |n| / `full_scale`). [`NO_FLOW`] when `confidence` is 0 or
/// the vector is zero or not finite.
pub fn flow_colour(nx: f32, ny: f32, confidence: f32, full_scale: f32) -> [u8; 4] {
    let m = nx.hypot(ny);
    if confidence.partial_cmp(&0.0) != Some(std::cmp::Ordering::Greater) || !m.is_finite() || m == 0.0 {
        return NO_FLOW;
    }
    let angle = f64::from(ny).atan2(f64::from(nx));
    let hue = angle / std::f64::consts::TAU;
    let v = 0.25 + 0.75 * f64::from((m / full_scale).min(1.0));
    let [r, g, b] = hsv(hue, 1.0, v);
    [r, g, b, 255]
}

/// Colour of an event of polarity `p` (1 = ON, else OFF).
pub fn polarity_colour(p: u8) -> [u8; 4] {
    if p == 1 { ON } else { OFF }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn hsv_primaries() {
        assert_eq!(hsv(0.0, 1.0, 1.0), [255, 0, 0]);
        assert_eq!(hsv(1.0 / 3.0, 1.0, 1.0), [0, 255, 0]);
        assert_eq!(hsv(2.0 / 3.0, 1.0, 1.0), [0, 0, 255]);
        assert_eq!(hsv(0.5, 0.0, 0.5), [128, 128, 128]);
        // Hue wraps around.
        assert_eq!(hsv(-1.0 / 3.0, 1.0, 1.0), hsv(2.0 / 3.0, 1.0, 1.0));
    }

    #[test]
    fn labels_are_stable_and_distinct() {
        assert_eq!(label_colour(0), BACKGROUND);
        assert_eq!(label_colour(u32::MAX), UNLABELLED);
        assert_eq!(label_colour(0xFFFF), UNLABELLED);
        assert_eq!(label_colour(3), label_colour(3));
        let colours: Vec<[u8; 4]> = (1..=12).map(label_colour).collect();
        for (i, a) in colours.iter().enumerate() {
            assert_ne!(*a, BACKGROUND);
            for b in &colours[i + 1..] {
                let d: i32 = a
                    .iter()
                    .zip(b)
                    .map(|(x, y)| (i32::from(*x) - i32::from(*y)).abs())
                    .sum();
                assert!(d > 30, "ids 1..=12 should differ visibly: {a:?} vs {b:?}");
            }
        }
    }

    #[test]
    fn flow_hue_follows_direction_and_brightness_magnitude() {
        // +x: red; +y (down): hue 90° -> (0.25 of the wheel) yellow-green; -x: cyan.
        assert_eq!(flow_colour(1.0, 0.0, 1.0, 1.0), [255, 0, 0, 255]);
        assert_eq!(flow_colour(0.0, 2.0, 1.0, 1.0), [128, 255, 0, 255]);
        assert_eq!(flow_colour(-1.0, 0.0, 0.5, 1.0), [0, 255, 255, 255]);
        // Half the full scale: brightness 0.25 + 0.375.
        let half = flow_colour(0.5, 0.0, 1.0, 1.0);
        assert_eq!(half, [159, 0, 0, 255]);
        // No estimate.
        assert_eq!(flow_colour(0.0, 0.0, 1.0, 1.0), NO_FLOW);
        assert_eq!(flow_colour(1.0, 0.0, 0.0, 1.0), NO_FLOW);
        assert_eq!(flow_colour(f32::NAN, 0.0, 1.0, 1.0), NO_FLOW);
        assert_eq!(flow_colour(1.0, 0.0, f32::NAN, 1.0), NO_FLOW);
    }

    #[test]
    fn polarity() {
        assert_eq!(polarity_colour(1), ON);
        assert_eq!(polarity_colour(0), OFF);
    }
}
