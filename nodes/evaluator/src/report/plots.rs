//! The report's plots: IoU over time, velocity per axis, object image motion, and frames of
//! events coloured by predicted label beside the ground truth.

use super::raster::{BLACK, Canvas, GRID, INK, Rgb, WHITE};
use crate::frames::{FrameSnapshot, NO_EVENT_ID, NO_EVENT_LABEL, UNKNOWN_TRUTH};
use evseg_schemas::Tracks;

/// How a series is drawn.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Style {
    /// Lines between consecutive finite points.
    Line,
    /// A marker per point.
    Markers,
    /// Both.
    LineMarkers,
}

/// One data series; NaN values break the line.
#[derive(Debug, Clone, PartialEq)]
pub struct Series {
    /// Legend text.
    pub name: String,
    /// Colour.
    pub color: Rgb,
    /// Points `(x, y)`.
    pub points: Vec<(f64, f64)>,
    /// Drawing style.
    pub style: Style,
}

/// One chart panel sharing the figure's x axis.
#[derive(Debug, Clone, PartialEq)]
pub struct Panel {
    /// Title above the panel.
    pub title: String,
    /// Y axis label (with unit).
    pub y_label: String,
    /// Series.
    pub series: Vec<Series>,
    /// Fixed y range, or `None` to fit the data.
    pub y_range: Option<(f64, f64)>,
}

/// Colours for series and labels, distinguishable and readable on white and black.
pub const PALETTE: [Rgb; 10] = [
    [31, 119, 180],
    [255, 127, 14],
    [44, 160, 44],
    [214, 39, 40],
    [148, 103, 189],
    [140, 86, 75],
    [227, 119, 194],
    [188, 189, 34],
    [23, 190, 207],
    [255, 221, 0],
];

const LEFT: i64 = 86;
const RIGHT: i64 = 24;
const TOP: i64 = 50;
const BOTTOM: i64 = 26;
const X_AXIS: i64 = 44;

/// A "nice" tick step (1, 2 or 5 times a power of ten) giving about `n` ticks over `span`.
pub fn nice_step(span: f64, n: usize) -> f64 {
    if !(span.is_finite() && span > 0.0) {
        return 1.0;
    }
    let raw = span / n.max(1) as f64;
    let p = 10f64.powf(raw.log10().floor());
    let m = raw / p;
    let k = if m < 1.5 {
        1.0
    } else if m < 3.5 {
        2.0
    } else if m < 7.5 {
        5.0
    } else {
        10.0
    };
    k * p
}

fn fmt_tick(v: f64, step: f64) -> String {
    let decimals = if step >= 1.0 {
        0
    } else {
        (-step.log10().floor()) as usize
    };
    let s = format!("{v:.decimals$}");
    if s.starts_with("-") && s.trim_start_matches(['-', '0', '.']).is_empty() {
        s[1..].to_string()
    } else {
        s
    }
}

fn range(values: impl Iterator<Item = f64>) -> Option<(f64, f64)> {
    let mut r: Option<(f64, f64)> = None;
    for v in values.filter(|v| v.is_finite()) {
        r = Some(r.map_or((v, v), |(a, b)| (a.min(v), b.max(v))));
    }
    r.map(|(a, b)| if b - a < 1e-12 { (a - 0.5, b + 0.5) } else { (a, b) })
}

/// Draws panels stacked vertically over a shared x axis labelled `x_label`.
pub fn chart(panels: &[Panel], x_label: &str, width: usize, panel_height: usize) -> Canvas {
    let n = panels.len().max(1);
    let height = n * panel_height + X_AXIS as usize;
    let mut c = Canvas::new(width, height, WHITE);
    let xr = range(
        panels
            .iter()
            .flat_map(|p| p.series.iter().flat_map(|s| s.points.iter().map(|p| p.0))),
    )
    .unwrap_or((0.0, 1.0));
    let x_step = nice_step(xr.1 - xr.0, 8);
    let (x0, x1) = (LEFT, width as i64 - RIGHT);
    let sx = |x: f64| x0 + ((x - xr.0) / (xr.1 - xr.0) * (x1 - x0) as f64).round() as i64;
    for (i, p) in panels.iter().enumerate() {
        let top = (i * panel_height) as i64;
        let (y0, y1) = (top + TOP, top + panel_height as i64 - BOTTOM);
        let yr = p
            .y_range
            .or_else(|| {
                range(p.series.iter().flat_map(|s| s.points.iter().map(|q| q.1))).map(|(a, b)| {
                    let pad = 0.06 * (b - a);
                    (a - pad, b + pad)
                })
            })
            .unwrap_or((0.0, 1.0));
        let sy = |y: f64| y1 - ((y - yr.0) / (yr.1 - yr.0) * (y1 - y0) as f64).round() as i64;
        // Grid and ticks.
        let y_step = nice_step(yr.1 - yr.0, 5);
        let mut t = (yr.0 / y_step).ceil() * y_step;
        while t <= yr.1 + 1e-9 * y_step {
            let py = sy(t);
            c.line(x0, py, x1, py, GRID, 1);
            let label = fmt_tick(t, y_step);
            let w = super::font::text_width(&label, 1) as i64;
            c.text(&label, x0 - 6 - w, py - 4, 1, INK);
            t += y_step;
        }
        let mut t = (xr.0 / x_step).ceil() * x_step;
        while t <= xr.1 + 1e-9 * x_step {
            let px = sx(t);
            c.line(px, y0, px, y1, GRID, 1);
            c.line(px, y1, px, y1 + 4, INK, 1);
            c.text_centered(&fmt_tick(t, x_step), px, y1 + 7, 1, INK);
            t += x_step;
        }
        if yr.0 < 0.0 && yr.1 > 0.0 {
            c.line(x0, sy(0.0), x1, sy(0.0), [170, 170, 170], 1);
        }
        c.stroke_rect(x0, y0, x1, y1, INK);
        c.text(&p.title, x0, top + 8, 2, BLACK);
        c.text_vertical(&p.y_label, 8, (y0 + y1) / 2, 1, INK);
        // Legend, right-aligned in the top margin.
        let mut lx = x1;
        for s in p.series.iter().rev() {
            let w = super::font::text_width(&s.name, 1) as i64;
            lx -= w + 22;
            c.fill_rect(lx, top + 34, lx + 14, top + 38, s.color);
            c.text(&s.name, lx + 18, top + 32, 1, INK);
            lx -= 14;
        }
        // Data, clipped to the plot area; earlier series are drawn bolder so that a later series
        // on the same values does not hide them.
        let count = p.series.len() as i64;
        for (si, s) in p.series.iter().enumerate() {
            let bold = (count - 1 - si as i64).min(2);
            let mut plot = Canvas::new((x1 - x0 + 1) as usize, (y1 - y0 + 1) as usize, WHITE);
            let mask_color = [1, 2, 3];
            plot.pixels.fill(mask_color);
            let mut prev: Option<(i64, i64)> = None;
            for &(x, y) in &s.points {
                if !(x.is_finite() && y.is_finite()) {
                    prev = None;
                    continue;
                }
                let (px, py) = (sx(x) - x0, sy(y) - y0);
                if matches!(s.style, Style::Line | Style::LineMarkers)
                    && let Some((qx, qy)) = prev
                {
                    plot.line(qx, qy, px, py, s.color, 2 + 2 * bold as usize);
                }
                if matches!(s.style, Style::Markers | Style::LineMarkers) {
                    plot.marker(px, py, 2 + bold, s.color);
                }
                prev = Some((px, py));
            }
            for yy in 0..plot.height {
                for xx in 0..plot.width {
                    let v = plot.pixels[yy * plot.width + xx];
                    if v != mask_color {
                        c.set(x0 + xx as i64, y0 + yy as i64, v);
                    }
                }
            }
        }
    }
    let base = (n * panel_height) as i64;
    c.text_centered(x_label, (x0 + x1) / 2, base + 18, 1, BLACK);
    c
}

/// Colour of a label or object id in the frame plots.
pub fn label_color(label: u32) -> Rgb {
    PALETTE[(label as usize).wrapping_sub(1) % PALETTE.len()]
}

/// Colour of a predicted label matched to no object (hatched look is not possible per pixel,
/// so a colour from the palette's second half, shifted by the label).
pub fn unmatched_color(label: u32) -> Rgb {
    PALETTE[(label as usize * 3 + 5) % PALETTE.len()].map(|c| c / 2 + 64)
}

const NO_EVENT: Rgb = [16, 16, 16];
const BACKGROUND_EVENT: Rgb = [120, 120, 120];
const UNKNOWN_EVENT: Rgb = [60, 60, 110];
/// Events labelled [`Tracks::UNCONFIRMED`]: moving, but their track is not confirmed yet.
const UNCONFIRMED_EVENT: Rgb = [215, 215, 215];

/// Importance of a pixel when several source pixels fall on one display pixel.
fn rank(c: Rgb) -> u8 {
    match c {
        NO_EVENT => 0,
        UNKNOWN_EVENT => 1,
        BACKGROUND_EVENT => 2,
        _ => 3,
    }
}

/// Rasterises `src(x, y)` colours of a `w x h` sensor into a panel `pw` pixels wide (block
/// reduction keeping the most important colour, or integer upscaling).
fn panel(w: usize, h: usize, pw: usize, src: impl Fn(usize, usize) -> Rgb) -> Canvas {
    let scale = pw as f64 / w as f64;
    let ph = ((h as f64 * scale).round() as usize).max(1);
    let mut c = Canvas::new(pw, ph, NO_EVENT);
    for py in 0..ph {
        let (sy0, sy1) = (
            (py as f64 / scale) as usize,
            (((py + 1) as f64 / scale).ceil() as usize).min(h),
        );
        for px in 0..pw {
            let (sx0, sx1) = (
                (px as f64 / scale) as usize,
                (((px + 1) as f64 / scale).ceil() as usize).min(w),
            );
            let mut best = NO_EVENT;
            for y in sy0..sy1.max(sy0 + 1).min(h) {
                for x in sx0..sx1.max(sx0 + 1).min(w) {
                    let v = src(x, y);
                    if rank(v) > rank(best) {
                        best = v;
                    }
                }
            }
            c.set(px as i64, py as i64, best);
        }
    }
    c
}

/// Height of a line of the frames figure's key, pixels.
const KEY_LINE: i64 = 18;

/// Frames side by side: per row, events coloured by predicted label (left) and by ground truth
/// (right); grey = background events, dark blue = events without ground truth, black = no event.
pub fn frames_figure(frames: &[&FrameSnapshot], panel_width: usize) -> Canvas {
    let gap = 12usize;
    let head = 30usize;
    let caption = 22usize;
    let rows: Vec<(Canvas, Canvas, String)> = frames
        .iter()
        .map(|f| {
            let (w, h) = (f.width as usize, f.height as usize);
            let pred = panel(w, h, panel_width, |x, y| match f.predicted[y * w + x] {
                NO_EVENT_LABEL => NO_EVENT,
                0 => BACKGROUND_EVENT,
                Tracks::UNCONFIRMED => UNCONFIRMED_EVENT,
                l => match f.matches.iter().find(|m| m.0 == l) {
                    Some(&(_, object)) => label_color(object as u32),
                    None => unmatched_color(l),
                },
            });
            let truth = panel(w, h, panel_width, |x, y| match f.truth[y * w + x] {
                NO_EVENT_ID => NO_EVENT,
                UNKNOWN_TRUTH => UNKNOWN_EVENT,
                0 => BACKGROUND_EVENT,
                id => label_color(id as u32),
            });
            let iou = f.iou.map_or("n/a".to_string(), |v| format!("{v:.3}"));
            let text = format!(
                "slice {}  t = {:.3}-{:.3} s  IoU {iou}",
                f.seq, f.t_start, f.t_end
            );
            (pred, truth, text)
        })
        .collect();
    let width = (2 * panel_width + 3 * gap).max(780);
    let height =
        head + rows.iter().map(|r| caption + r.0.height + gap).sum::<usize>() + 4 * KEY_LINE as usize;
    let mut c = Canvas::new(width, height, WHITE);
    let left = gap as i64;
    let right = (2 * gap + panel_width) as i64;
    c.text_centered("predicted label", left + panel_width as i64 / 2, 8, 2, BLACK);
    c.text_centered("ground truth", right + panel_width as i64 / 2, 8, 2, BLACK);
    let mut y = head as i64;
    for (pred, truth, text) in &rows {
        c.text(text, left, y + 6, 1, INK);
        y += caption as i64;
        c.blit(pred, left, y);
        c.blit(truth, right, y);
        y += (pred.height + gap) as i64;
    }
    let key = [
        (BACKGROUND_EVENT, "background event"),
        (UNCONFIRMED_EVENT, "moving, track not confirmed"),
        (UNKNOWN_EVENT, "no truth (away from mask time)"),
        (NO_EVENT, "no event"),
    ];
    let mut x = left;
    for (col, name) in key {
        let item = 16 + super::font::text_width(name, 1) as i64;
        if x > left && x + item > width as i64 - gap as i64 {
            x = left;
            y += KEY_LINE;
        }
        c.fill_rect(x, y + 4, x + 12, y + 14, col);
        c.text(name, x + 16, y + 5, 1, INK);
        x += item + 20;
    }
    for (k, line) in [
        "colours: one per object; a predicted label takes its matched object's colour,",
        "a label matched to no object a dimmed colour of its own",
    ]
    .into_iter()
    .enumerate()
    {
        c.text(line, left, y + KEY_LINE * (k as i64 + 1), 1, INK);
    }
    c
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn nice_steps() {
        assert_eq!(nice_step(1.0, 5), 0.2);
        assert_eq!(nice_step(10.0, 8), 1.0);
        assert_eq!(nice_step(0.03, 5), 0.005);
        assert_eq!(fmt_tick(-0.0, 0.1), "0.0");
        assert_eq!(fmt_tick(0.25, 0.05), "0.25");
    }

    #[test]
    fn chart_draws_series_inside_the_plot_area() {
        let p = Panel {
            title: "t".into(),
            y_label: "y".into(),
            series: vec![Series {
                name: "s".into(),
                color: [255, 0, 0],
                points: vec![(0.0, 0.0), (1.0, 1.0), (2.0, f64::NAN), (3.0, 0.5)],
                style: Style::LineMarkers,
            }],
            y_range: Some((0.0, 1.0)),
        };
        let c = chart(&[p], "x", 400, 200);
        let red = c.pixels.iter().filter(|&&v| v == [255, 0, 0]).count();
        assert!(red > 100, "{red}");
        // Bottom-left data point (0, 0) at the plot's corner.
        assert_eq!(
            c.get(LEFT as usize + 1, (200 - BOTTOM) as usize - 1),
            Some([255, 0, 0])
        );
    }

    #[test]
    fn frames_show_unconfirmed_events_apart_from_pixels_without_events() {
        // A 4 x 2 sensor: one background event, one unconfirmed, one with a track id; the
        // other five pixels have no event.
        let labels = [0, Tracks::UNCONFIRMED, 7];
        let truth = vec![0, 1, 1];
        let f = FrameSnapshot::new(
            0,
            (0.0, 0.03),
            (4, 2),
            (&[0, 1, 2], &[0, 0, 0]),
            &labels,
            &truth,
            None,
        );
        let c = frames_figure(&[&f], 4);
        let count = |col: Rgb| c.pixels.iter().filter(|&&v| v == col).count();
        // Panels are rasterised at 1:1 here; the key draws a 12 x 10 swatch of each colour.
        let swatch = 12 * 10;
        assert_eq!(count(UNCONFIRMED_EVENT), 1 + swatch);
        assert_eq!(count(BACKGROUND_EVENT), 2 + swatch);
        assert_eq!(count(unmatched_color(7)), 1);
    }
}
