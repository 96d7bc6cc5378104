//! `sequence.html`: PSNR, splats and time per frame as plots, temporal stability, and a table of
//! every frame with a link to its own report.

use std::fmt::Write as _;
use std::path::Path;

use super::SequenceError;
use super::manifest::{FrameState, SequenceManifest};
use crate::plot::{self, COLOURS, Series, esc};
use crate::report::human_bytes;

/// Writes `DIR/sequence.html` atomically.
pub fn write(out: &Path, manifest: &SequenceManifest) -> Result<(), SequenceError> {
    let path = out.join("sequence.html");
    atomic_output::write_atomic(&path, render(manifest).as_bytes())
        .map_err(|source| SequenceError::Io { path, source })
}

/// (frame number from 1, value) of the finished frames.
fn per_frame(m: &SequenceManifest, value: impl Fn(&super::FrameResult) -> f64) -> Vec<(f64, f64)> {
    m.frames
        .iter()
        .enumerate()
        .filter_map(|(i, r)| r.result.as_ref().map(|x| ((i + 1) as f64, value(x))))
        .collect()
}

fn series(label: &str, colour: &'static str, points: Vec<(f64, f64)>) -> Series {
    Series {
        label: label.into(),
        title: label.into(),
        colour,
        dashed: false,
        points,
    }
}

fn axes(y: &str, round_y: bool) -> plot::Axes {
    plot::Axes {
        x_label: "frame".into(),
        y_label: y.into(),
        round_y,
        integer_x: true,
    }
}

/// The page.
#[must_use]
pub fn render(m: &SequenceManifest) -> String {
    let mut h = String::from(
        "<!doctype html><html><head><meta charset=\"utf-8\"><title>Sequence report</title>\
         <style>body{font-family:sans-serif;margin:2em;max-width:1100px}\
         table{border-collapse:collapse}td,th{border:1px solid #ccc;padding:3px 8px;text-align:right}\
         td:first-child,th:first-child{text-align:left}.failed{color:#b00}</style></head><body>\n",
    );
    summary(&mut h, m);
    per_frame_plots(&mut h, m);
    temporal_plot(&mut h, m);
    frames_table(&mut h, m);
    consecutive_table(&mut h, m);
    h.push_str("</body></html>\n");
    h
}

/// The title and how many frames are in each state, with the frame times.
fn summary(h: &mut String, m: &SequenceManifest) {
    let s = &m.summary;
    let _ = writeln!(
        h,
        "<h1>Sequence: {}</h1>\n<p>{} frames: {} finished, {} failed, {} running or killed, \
         {} pending. Frame time (load to report): median {} cold, {} warm; {:.0} s in all.</p>",
        esc(&m.input),
        s.frames,
        s.finished,
        s.failed,
        s.running,
        s.pending,
        s.cold_seconds_median
            .map_or("–".into(), |t| format!("{t:.1} s")),
        s.warm_seconds_median
            .map_or("–".into(), |t| format!("{t:.1} s")),
        s.total_seconds
    );
}

/// Held-out PSNR, time and splats against the frame number.
fn per_frame_plots(h: &mut String, m: &SequenceManifest) {
    h.push_str("<h2>Held-out PSNR per frame</h2>\n");
    h.push_str(&plot::svg(
        &axes("PSNR (dB)", true),
        &[
            series("black", COLOURS[0], per_frame(m, |x| x.psnr_black)),
            series("white", COLOURS[1], per_frame(m, |x| x.psnr_white)),
            series(
                "masked (object only), black",
                COLOURS[2],
                per_frame(m, |x| x.masked_psnr_black),
            ),
        ],
        &[],
    ));
    h.push_str("<h2>Time per frame</h2>\n");
    h.push_str(&plot::svg(
        &axes("seconds", false),
        &[
            series("whole frame", COLOURS[0], per_frame(m, |x| x.seconds)),
            series("training", COLOURS[1], per_frame(m, |x| x.train_seconds)),
        ],
        &[],
    ));
    h.push_str("<h2>Splats per frame</h2>\n");
    h.push_str(&plot::svg(
        &axes("splats", false),
        &[series(
            "splats",
            COLOURS[0],
            per_frame(m, |x| x.splats as f64),
        )],
        &[],
    ));
}

/// Consecutive frames' renders against each other, beside the references'.
fn temporal_plot(h: &mut String, m: &SequenceManifest) {
    h.push_str(
        "<h2>Temporal stability</h2>\n<p>PSNR between consecutive frames' renders of the same \
         held-out cameras, beside the same figure for the reference views: where the models' \
         line falls below the references', the models change more than the input does \
         (flicker).</p>\n",
    );
    let index_of = |name: &str| m.frames.iter().position(|r| r.name == name).unwrap_or(0) + 1;
    h.push_str(&plot::svg(
        &axes("PSNR to the previous frame (dB)", true),
        &[
            series(
                "models",
                COLOURS[0],
                m.temporal
                    .iter()
                    .map(|p| (index_of(&p.frame) as f64, p.model_psnr))
                    .collect(),
            ),
            series(
                "references",
                COLOURS[1],
                m.temporal
                    .iter()
                    .map(|p| (index_of(&p.frame) as f64, p.reference_psnr))
                    .collect(),
            ),
        ],
        &[],
    ));
}

/// A relative path as a URL path: each segment's bytes outside the unreserved characters
/// percent-encoded (a frame named `take#2` linked to `take`, fragment `2`).
fn url_path(path: &Path) -> String {
    path.iter()
        .map(|segment| {
            segment
                .to_string_lossy()
                .bytes()
                .map(|b| {
                    if b.is_ascii_alphanumeric() || b"-._~".contains(&b) {
                        char::from(b).to_string()
                    } else {
                        format!("%{b:02X}")
                    }
                })
                .collect::<String>()
        })
        .collect::<Vec<_>>()
        .join("/")
}

/// Every frame: its state, start, figures, and a link to its own report once finished.
fn frames_table(h: &mut String, m: &SequenceManifest) {
    h.push_str(
        "<h2>Frames</h2>\n<table><tr><th>frame</th><th>state</th><th>start</th><th>steps</th>\
         <th>PSNR black / white (dB)</th><th>masked (dB)</th><th>SSIM</th><th>splats</th>\
         <th>PLY</th><th>SPZ</th><th>time (s)</th><th>training (s)</th></tr>\n",
    );
    for r in &m.frames {
        let link = r.dir.join("report").join("report.html");
        let name = if r.state == FrameState::Finished {
            format!("<a href=\"{}\">{}</a>", esc(&url_path(&link)), esc(&r.name))
        } else {
            esc(&r.name)
        };
        let start = r
            .warm_start
            .as_ref()
            .map_or("cold".to_string(), |p| format!("warm from {}", esc(p)));
        let state = match (&r.state, &r.error) {
            (FrameState::Failed, Some(e)) => {
                format!("<span class=\"failed\" title=\"{}\">failed</span>", esc(e))
            }
            (state, _) => format!("{state:?}").to_lowercase(),
        };
        let _ = write!(h, "<tr><td>{name}</td><td>{state}</td><td>{start}</td>");
        match &r.result {
            Some(x) => {
                let _ = writeln!(
                    h,
                    "<td>{}</td><td>{:.2} / {:.2}</td><td>{:.2}</td><td>{:.4}</td><td>{}</td>\
                     <td>{}</td><td>{}</td><td>{:.1}</td><td>{:.1}</td></tr>",
                    x.iterations,
                    x.psnr_black,
                    x.psnr_white,
                    x.masked_psnr_black,
                    x.ssim_black,
                    x.splats,
                    human_bytes(x.model_bytes),
                    x.spz_bytes.map_or("–".into(), human_bytes),
                    x.seconds,
                    x.train_seconds
                );
            }
            None => h.push_str("<td colspan=\"9\"></td></tr>\n"),
        }
    }
    h.push_str("</table>\n");
}

/// The temporal stability figures frame pair by frame pair.
fn consecutive_table(h: &mut String, m: &SequenceManifest) {
    if !m.temporal.is_empty() {
        h.push_str(
            "<h2>Consecutive frames</h2>\n<table><tr><th>frames</th><th>models (dB)</th>\
             <th>references (dB)</th><th>views</th></tr>\n",
        );
        for p in &m.temporal {
            let _ = writeln!(
                h,
                "<tr><td>{} → {}</td><td>{:.2}</td><td>{:.2}</td><td>{}</td></tr>",
                esc(&p.previous),
                esc(&p.frame),
                p.model_psnr,
                p.reference_psnr,
                p.views
            );
        }
        h.push_str("</table>\n");
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn links_to_frames_are_url_paths() {
        let link = Path::new("frames/take#2 ?50%/report/report.html");
        assert_eq!(
            url_path(link),
            "frames/take%232%20%3F50%25/report/report.html"
        );
        assert_eq!(
            url_path(Path::new("frames/été_1")),
            "frames/%C3%A9t%C3%A9_1"
        );
    }
}
