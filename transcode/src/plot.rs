//! Inline SVG line plots for the reports: axes with five ticks, solid or dashed lines with a
//! legend, and labelled markers. Written by hand because the reports are single self-contained
//! HTML files and the plots are a few dozen lines of SVG; a plotting crate would bring fonts and
//! raster backends for nothing.

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
    /// Round the y range out to whole units (dB plots) rather than keep it as it is.
    pub round_y: bool,
}

/// The plot as an `<svg>` element; a note when there is nothing to plot.
#[must_use]
pub fn svg(axes: &Axes, series: &[Series], markers: &[Marker]) -> String {
    let (w, h, left, bottom, top, right) = (720.0, 360.0, 60.0, 40.0, 15.0, 20.0);
    let points: Vec<(f64, f64)> = series
        .iter()
        .flat_map(|s| s.points.iter().copied())
        .chain(markers.iter().map(|m| (m.0, m.1)))
        .filter(|p| p.0.is_finite() && p.1.is_finite())
        .collect();
    if points.is_empty() {
        return "<p>(nothing to plot)</p>\n".into();
    }
    let x_max = points.iter().map(|p| p.0).fold(0.0, f64::max).max(1e-3);
    let y_lo = points.iter().map(|p| p.1).fold(f64::INFINITY, f64::min);
    let y_hi = points.iter().map(|p| p.1).fold(f64::NEG_INFINITY, f64::max);
    let (y_min, y_max) = if axes.round_y {
        (y_lo.floor(), y_hi.ceil())
    } else {
        (y_lo.min(0.0), y_hi)
    };
    let y_max = if y_max <= y_min { y_min + 1.0 } else { y_max };
    let x = |v: f64| left + (w - left - right) * v / x_max;
    let y = |v: f64| top + (h - top - bottom) * (1.0 - (v - y_min) / (y_max - y_min));
    let mut s = format!(
        "<svg xmlns=\"http://www.w3.org/2000/svg\" width=\"{w}\" height=\"{h}\" viewBox=\"0 0 {w} {h}\" \
         font-size=\"12\"><rect width=\"{w}\" height=\"{h}\" fill=\"white\"/>\
         <line x1=\"{left}\" y1=\"{yb}\" x2=\"{xr}\" y2=\"{yb}\" stroke=\"black\"/>\
         <line x1=\"{left}\" y1=\"{top}\" x2=\"{left}\" y2=\"{yb}\" stroke=\"black\"/>",
        yb = h - bottom,
        xr = w - right
    );
    let y_decimals = if y_max - y_min < 10.0 { 1 } else { 0 };
    for k in 0..=5 {
        let t = x_max * f64::from(k) / 5.0;
        let _ = write!(
            s,
            "<text x=\"{:.1}\" y=\"{:.1}\" text-anchor=\"middle\">{}</text>",
            x(t),
            h - bottom + 16.0,
            tick(t)
        );
        let p = y_min + (y_max - y_min) * f64::from(k) / 5.0;
        let _ = write!(
            s,
            "<text x=\"{:.1}\" y=\"{:.1}\" text-anchor=\"end\">{p:.y_decimals$}</text>\
             <line x1=\"{left}\" y1=\"{yy:.1}\" x2=\"{xr}\" y2=\"{yy:.1}\" stroke=\"#eee\"/>",
            left - 6.0,
            y(p) + 4.0,
            yy = y(p),
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
    let mut legend = 0;
    for line in series {
        let pts: Vec<String> = line
            .points
            .iter()
            .filter(|p| p.0.is_finite() && p.1.is_finite())
            .map(|&(a, b)| format!("{:.1},{:.1}", x(a), y(b)))
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
                "<text x=\"{:.1}\" y=\"{:.1}\" fill=\"{}\">{}</text>",
                left + 10.0,
                top + 14.0 + 16.0 * f64::from(legend),
                line.colour,
                esc(&line.label)
            );
            legend += 1;
        }
    }
    for (mx, my, label, colour) in markers {
        let _ = write!(
            s,
            "<circle cx=\"{:.1}\" cy=\"{:.1}\" r=\"4\" fill=\"white\" stroke=\"{colour}\" \
             stroke-width=\"2\"><title>{}: {my:.2}</title></circle>\
             <text x=\"{:.1}\" y=\"{:.1}\" fill=\"{colour}\" font-size=\"10\">{}</text>",
            x(*mx),
            y(*my),
            esc(label),
            x(*mx) + 6.0,
            y(*my) - 6.0,
            esc(label)
        );
    }
    s.push_str("</svg>\n");
    s
}

/// An x-axis tick: whole numbers as such, small values with two significant decimals.
fn tick(v: f64) -> String {
    if v >= 10.0 || v == v.round() {
        format!("{v:.0}")
    } else {
        format!("{v:.2}")
    }
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
        let expected = 15.0 + 305.0 * (1.0 - 0.2 / 11.0);
        assert!((coords[0].1 - expected).abs() < 0.06);
        assert_eq!(svg(&axes, &[], &[]), "<p>(nothing to plot)</p>\n");
    }
}
