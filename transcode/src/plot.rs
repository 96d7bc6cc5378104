//! Inline SVG line plots for the reports: axes with round ticks (1, 2, 2.5 or 5 times a power
//! of ten, about five to an axis), solid or dashed lines with a legend, and labelled markers.
//! Written by hand because the reports are single self-contained HTML files and the plots are a
//! few dozen lines of SVG; a plotting crate would bring fonts and raster backends for nothing.

use std::fmt::Write;

/// Line colours, in turn.
pub const COLOURS: [&str; 4] = ["#1f77b4", "#d62728", "#2ca02c", "#9467bd"];

/// One line of a plot.
#[derive(Debug, Clone, Default)]
pub struct Series {
    /// Shown in the legend; empty: no legend entry (the line still shows `title` on hover).
    pub label: String,
    /// Shown on hover.
    pub title: String,
    /// CSS colour.
    pub colour: &'static str,
    /// Dashed instead of solid.
    pub dashed: bool,
    /// (x, y) points, drawn in order.
    pub points: Vec<(f64, f64)>,
}

/// A labelled point: (x, y, label, colour).
pub type Marker = (f64, f64, String, &'static str);

/// The plot's size and axis labels.
#[derive(Debug, Clone)]
pub struct Axes {
    /// x-axis label.
    pub x_label: String,
    /// y-axis label.
    pub y_label: String,
    /// Fit the y range to the data (dB plots) rather than start it at zero.
    pub round_y: bool,
    /// Whole-number x ticks only (frame numbers), and the x range fitted to the data rather than
    /// started at zero.
    pub integer_x: bool,
}

/// Round ticks covering `lo..=hi`: a step of 1, 2, 2.5 or 5 times a power of ten giving about
/// five intervals (at least `min_step`), the range rounded out to whole steps.
#[must_use]
pub fn ticks(lo: f64, hi: f64, min_step: f64) -> Vec<f64> {
    // A flat line gets a range of one unit around it.
    let (lo, hi) = if hi - lo < 1e-9 * hi.abs().max(1.0) {
        (lo - 0.5, hi + 0.5)
    } else {
        (lo, hi)
    };
    let raw = (hi - lo) / 5.0;
    let power = 10f64.powf(raw.log10().floor());
    let step = [1.0, 2.0, 2.5, 5.0, 10.0]
        .iter()
        .map(|m| m * power)
        .find(|&s| s >= raw)
        .unwrap_or(10.0 * power)
        .max(min_step);
    // (A bound within rounding error of a tick is that tick.)
    let first = (lo / step + 1e-9).floor();
    let last = (hi / step - 1e-9).ceil();
    // At most a few dozen ticks: `step` is at least a fifth of the span.
    (first as i64..=last as i64)
        .map(|k| k as f64 * step)
        .collect()
}

/// The plot as an `<svg>` element; a note when there is nothing to plot.
#[must_use]
pub fn svg(axes: &Axes, series: &[Series], markers: &[Marker]) -> String {
    let points: Vec<(f64, f64)> = series
        .iter()
        .flat_map(|s| s.points.iter().copied())
        .chain(markers.iter().map(|m| (m.0, m.1)))
        .filter(|p| p.0.is_finite() && p.1.is_finite())
        .collect();
    let Some(frame) = Frame::fitted(axes, &points) else {
        return "<p>(nothing to plot)</p>\n".into();
    };
    let mut s = frame.axes(axes);
    let mut legend = 0;
    for line in series {
        frame.line(&mut s, line, &mut legend);
    }
    for marker in markers {
        frame.marker(&mut s, marker);
    }
    s.push_str("</svg>\n");
    s
}

/// The plot's geometry: the SVG's size, the plot area's margins, and the ticks, whose first
/// and last values are the ends of each axis.
struct Frame {
    x_ticks: Vec<f64>,
    y_ticks: Vec<f64>,
}

impl Frame {
    const WIDTH: f64 = 720.0;
    const HEIGHT: f64 = 360.0;
    const LEFT: f64 = 60.0;
    const BOTTOM: f64 = 40.0;
    const TOP: f64 = 15.0;
    const RIGHT: f64 = 20.0;

    /// Axes with round ticks covering `points`; none when there are no points.
    fn fitted(axes: &Axes, points: &[(f64, f64)]) -> Option<Self> {
        if points.is_empty() {
            return None;
        }
        let range = |f: fn(&(f64, f64)) -> f64| {
            points
                .iter()
                .map(f)
                .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), v| {
                    (a.min(v), b.max(v))
                })
        };
        let (x_lo, x_hi) = range(|p| p.0);
        let (y_lo, y_hi) = range(|p| p.1);
        let x_ticks = if axes.integer_x {
            ticks(x_lo, x_hi, 1.0)
        } else {
            ticks(x_lo.min(0.0), x_hi, 0.0)
        };
        let y_ticks = if axes.round_y {
            ticks(y_lo, y_hi, 0.0)
        } else {
            ticks(y_lo.min(0.0), y_hi, 0.0)
        };
        Some(Self { x_ticks, y_ticks })
    }

    /// The SVG x coordinate of data value `v`.
    fn x(&self, v: f64) -> f64 {
        let (lo, hi) = (self.x_ticks[0], self.x_ticks[self.x_ticks.len() - 1]);
        Self::LEFT + (Self::WIDTH - Self::LEFT - Self::RIGHT) * (v - lo) / (hi - lo)
    }

    /// The SVG y coordinate of data value `v` (SVG's y grows downwards).
    fn y(&self, v: f64) -> f64 {
        let (lo, hi) = (self.y_ticks[0], self.y_ticks[self.y_ticks.len() - 1]);
        Self::TOP + (Self::HEIGHT - Self::TOP - Self::BOTTOM) * (1.0 - (v - lo) / (hi - lo))
    }

    /// The opening `<svg>` tag, the background, the axes with their ticks, grid lines and labels.
    fn axes(&self, axes: &Axes) -> String {
        let (w, h, left, bottom, top, right) = (
            Self::WIDTH,
            Self::HEIGHT,
            Self::LEFT,
            Self::BOTTOM,
            Self::TOP,
            Self::RIGHT,
        );
        let mut s = format!(
            "<svg xmlns=\"http://www.w3.org/2000/svg\" width=\"{w}\" height=\"{h}\" viewBox=\"0 0 {w} {h}\" \
             font-size=\"12\"><rect width=\"{w}\" height=\"{h}\" fill=\"white\"/>\
             <line x1=\"{left}\" y1=\"{yb}\" x2=\"{xr}\" y2=\"{yb}\" stroke=\"black\"/>\
             <line x1=\"{left}\" y1=\"{top}\" x2=\"{left}\" y2=\"{yb}\" stroke=\"black\"/>",
            yb = h - bottom,
            xr = w - right
        );
        for &t in &self.x_ticks {
            let _ = write!(
                s,
                "<text x=\"{:.1}\" y=\"{:.1}\" text-anchor=\"middle\">{}</text>",
                self.x(t),
                h - bottom + 16.0,
                tick(t, self.x_ticks[1] - self.x_ticks[0])
            );
        }
        for &p in &self.y_ticks {
            let _ = write!(
                s,
                "<text x=\"{:.1}\" y=\"{:.1}\" text-anchor=\"end\">{}</text>\
                 <line x1=\"{left}\" y1=\"{yy:.1}\" x2=\"{xr}\" y2=\"{yy:.1}\" stroke=\"#eee\"/>",
                left - 6.0,
                self.y(p) + 4.0,
                tick(p, self.y_ticks[1] - self.y_ticks[0]),
                yy = self.y(p),
                xr = w - right
            );
        }
        let _ = write!(
            s,
            "<text x=\"{:.1}\" y=\"{:.1}\" text-anchor=\"middle\">{}</text>\
             <text x=\"14\" y=\"{:.1}\" text-anchor=\"middle\" transform=\"rotate(-90 14 {:.1})\">{}</text>",
            left + (w - left - right) / 2.0,
            h - 4.0,
            esc(&axes.x_label),
            h / 2.0,
            h / 2.0,
            esc(&axes.y_label)
        );
        s
    }

    /// One series as a polyline (its finite points), and its legend entry as the `legend`-th
    /// when it has a label.
    fn line(&self, s: &mut String, line: &Series, legend: &mut u32) {
        let pts: Vec<String> = line
            .points
            .iter()
            .filter(|p| p.0.is_finite() && p.1.is_finite())
            .map(|&(a, b)| format!("{:.1},{:.1}", self.x(a), self.y(b)))
            .collect();
        let dash = if line.dashed {
            " stroke-dasharray=\"5 3\""
        } else {
            ""
        };
        let _ = write!(
            s,
            "<polyline fill=\"none\" stroke=\"{}\" stroke-width=\"1.5\"{dash} points=\"{}\">\
             <title>{}</title></polyline>",
            line.colour,
            pts.join(" "),
            esc(&line.title)
        );
        if !line.label.is_empty() {
            let _ = write!(
                s,
                "<text x=\"{:.1}\" y=\"{:.1}\" fill=\"{}\" stroke=\"white\" stroke-width=\"3\" paint-order=\"stroke\">{}</text>",
                Self::LEFT + 10.0,
                Self::TOP + 14.0 + 16.0 * f64::from(*legend),
                line.colour,
                esc(&line.label)
            );
            *legend += 1;
        }
    }

    /// A marker: a ringed point with its label beside it and its value on hover.
    fn marker(&self, s: &mut String, (mx, my, label, colour): &Marker) {
        let _ = write!(
            s,
            "<circle cx=\"{:.1}\" cy=\"{:.1}\" r=\"4\" fill=\"white\" stroke=\"{colour}\" \
             stroke-width=\"2\"><title>{}: {my:.2}</title></circle>\
             <text x=\"{:.1}\" y=\"{:.1}\" fill=\"{colour}\" font-size=\"10\">{}</text>",
            self.x(*mx),
            self.y(*my),
            esc(label),
            self.x(*mx) + 6.0,
            self.y(*my) - 6.0,
            esc(label)
        );
    }
}

/// A tick's label, with as many decimals as the step between ticks needs (none for whole steps,
/// thousands separated by nothing: the reports' step counts are short).
fn tick(v: f64, step: f64) -> String {
    let decimals = if step >= 1.0 && step.fract() == 0.0 {
        0
    } else {
        // 0.5 → 1, 0.25 → 2, 0.2 → 1, 0.05 → 2.
        (1..=6)
            .find(|&d| {
                let scaled = step * 10f64.powi(d);
                (scaled - scaled.round()).abs() < 1e-6
            })
            .unwrap_or(6) as usize
    };
    format!("{v:.decimals$}")
}

/// Escapes text for HTML and SVG.
#[must_use]
pub fn esc(s: &str) -> String {
    s.replace('&', "&amp;")
        .replace('<', "&lt;")
        .replace('>', "&gt;")
        .replace('"', "&quot;")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn points_land_inside_the_plot_area_and_text_is_escaped() {
        let axes = Axes {
            x_label: "x <s>".into(),
            y_label: "y".into(),
            round_y: true,
            integer_x: false,
        };
        let line = Series {
            label: "a & b".into(),
            title: "t".into(),
            colour: COLOURS[0],
            dashed: true,
            points: vec![(0.0, 30.2), (10.0, 40.7), (f64::NAN, 1.0)],
        };
        let out = svg(&axes, &[line], &[(5.0, 35.0, "m".into(), COLOURS[1])]);
        assert!(out.contains("x &lt;s&gt;") && out.contains("a &amp; b"));
        assert!(out.contains("stroke-dasharray"));
        // y from 30 to 41: x 0 → 60 px, x 10 → 700 px; y 30.2 → near the bottom (320 px).
        let pts = out
            .split("points=\"")
            .nth(1)
            .unwrap()
            .split('"')
            .next()
            .unwrap();
        let coords: Vec<(f64, f64)> = pts
            .split(' ')
            .map(|p| {
                let (a, b) = p.split_once(',').unwrap();
                (a.parse().unwrap(), b.parse().unwrap())
            })
            .collect();
        assert_eq!(coords.len(), 2);
        assert_eq!(coords[0].0, 60.0);
        assert_eq!(coords[1].0, 700.0);
        // y ticks every 2.5 dB from 30 to 42.5.
        let expected = 15.0 + 305.0 * (1.0 - 0.2 / 12.5);
        assert!((coords[0].1 - expected).abs() < 0.06);
        assert!(out.contains(">42.5<") && out.contains(">30.0<"));
        assert_eq!(svg(&axes, &[], &[]), "<p>(nothing to plot)</p>\n");
    }

    #[test]
    fn ticks_are_round_and_cover_the_range() {
        let close = |a: Vec<f64>, b: &[f64]| {
            a.len() == b.len() && a.iter().zip(b).all(|(x, y)| (x - y).abs() < 1e-9)
        };
        // Frame numbers: whole steps from the first frame.
        assert!(close(ticks(1.0, 6.0, 1.0), &[1., 2., 3., 4., 5., 6.]));
        assert!(close(ticks(1.0, 300.0, 1.0), &[0., 100., 200., 300.]));
        assert!(close(ticks(1.0, 2.0, 1.0), &[1., 2.]));
        // dB: steps of 1, 2, 2.5 or 5 times a power of ten.
        assert!(close(ticks(27.5, 43.7, 0.0), &[25., 30., 35., 40., 45.]));
        assert!(close(
            ticks(32.35, 33.98, 0.0),
            &[32.0, 32.5, 33.0, 33.5, 34.0]
        ));
        assert!(close(ticks(0.0, 3000.0, 0.0), &[0., 1000., 2000., 3000.]));
        // A flat line: one unit around it.
        let flat = ticks(8082.0, 8082.0, 0.0);
        assert!(flat.len() >= 3 && flat[0] < 8082.0 && flat[flat.len() - 1] > 8082.0);
        assert_eq!(tick(2.5, 2.5), "2.5");
        assert_eq!(tick(30.0, 0.25), "30.00");
        assert_eq!(tick(3000.0, 1000.0), "3000");
    }
}
