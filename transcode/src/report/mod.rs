//! The run report: report.json and a self-contained report.html.
//!
//! The HTML page's own content needs nothing beside it: pictures are PNG data URIs, the training
//! curve is inline SVG. It shows, for several held-out views, the reference, each run's splats
//! and an error heat map side by side; the metrics of every run (surface and sparse init when both
//! ran); the time of each stage; and held-out-independent training PSNR against wall time. Its
//! one script is the interactive viewer, in the `viewer/` folder the pipeline writes beside it
//! ([`crate::viewer`]).

mod budget;

use std::fmt::Write as _;
use std::io;
use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

use crate::config::Config;
use crate::plot::{self, esc};
use atomic_output::write_atomic;
use splat_init::InitSummary;
use splat_train::eval::Metrics;

/// What the input was.
#[derive(Debug, Clone, Serialize)]
pub struct InputInfo {
    /// The file.
    pub path: PathBuf,
    /// "plenoptic cloud", "point cloud" or "mesh".
    pub kind: String,
    /// Points (clouds) or vertices (meshes).
    pub points: usize,
    /// Triangles (0 for clouds).
    pub triangles: usize,
    /// Capture cameras of a plenoptic input (0 otherwise).
    pub capture_cameras: usize,
    /// Size of the file in bytes.
    pub bytes: u64,
}

/// Wall time of one stage.
#[derive(Debug, Clone, Serialize)]
pub struct StageTiming {
    /// Stage name.
    pub stage: String,
    /// Seconds.
    pub seconds: f64,
}

/// One point of the training curve.
#[derive(Debug, Clone, Copy, Serialize)]
pub struct CurvePoint {
    /// Iteration.
    pub iteration: u32,
    /// Seconds since training started.
    pub elapsed_s: f64,
    /// Training-view PSNR (dB) of that step's view.
    pub psnr: f64,
    /// Splats at that step.
    pub splats: usize,
}

/// Held-out scores of a model before any training step.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct HeldoutScore {
    /// PSNR (dB) on black.
    pub psnr_black: f64,
    /// PSNR (dB) on white.
    pub psnr_white: f64,
    /// Masked (object-only) PSNR (dB) on black.
    pub masked_psnr_black: f64,
    /// Masked PSNR (dB) on white.
    pub masked_psnr_white: f64,
}

impl From<&Metrics> for HeldoutScore {
    fn from(m: &Metrics) -> Self {
        Self {
            psnr_black: m.psnr_black,
            psnr_white: m.psnr_white,
            masked_psnr_black: m.masked_psnr_black,
            masked_psnr_white: m.masked_psnr_white,
        }
    }
}

/// One point of the held-out curve (`eval.every`): the model scored on the held-out views
/// during training.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct HeldoutPoint {
    /// Steps done (0: the initial splats).
    pub iteration: u32,
    /// Training time in seconds up to that step (scoring excluded).
    pub elapsed_s: f64,
    /// Splats at that step.
    pub splats: usize,
    /// PSNRs on black and white, full and masked.
    #[serde(flatten)]
    pub score: HeldoutScore,
    /// Mean SSIM on black.
    pub ssim_black: f64,
    /// Mean SSIM on white.
    pub ssim_white: f64,
}

impl HeldoutPoint {
    /// The point of `metrics` taken after `iteration` steps and `elapsed_s` seconds of training.
    #[must_use]
    pub fn new(iteration: u32, elapsed_s: f64, metrics: &Metrics) -> Self {
        Self {
            iteration,
            elapsed_s,
            splats: metrics.splats,
            score: HeldoutScore::from(metrics),
            ssim_black: metrics.ssim_black,
            ssim_white: metrics.ssim_white,
        }
    }
}

/// What the initialisation alone is worth: held-out scores at step 0 of the per-camera SH fit
/// and, when it ran, of the least-squares colour solve that followed it.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct StepZero {
    /// The initial splats as initialisation made them (for surface init: the per-camera fit).
    pub fit: HeldoutScore,
    /// After the colour solve.
    pub solved: Option<HeldoutScore>,
    /// The solve's record.
    pub solve: Option<splat_init::SolveReport>,
    /// Seconds the solve took.
    pub solve_seconds: f64,
}

/// One initialise-train-evaluate run.
#[derive(Debug, Clone, Serialize)]
pub struct RunReport {
    /// What initialisation did.
    pub init: InitSummary,
    /// Steps run.
    pub iterations: u32,
    /// Training wall time in seconds.
    pub train_seconds: f64,
    /// True when the time budget stopped training.
    pub stopped_by_budget: bool,
    /// The mean step of the planned run by the probe before training (under a time budget):
    /// its warm-up and full-size steps in their planned shares.
    #[serde(default)]
    pub step_estimate_s: Option<f64>,
    /// The seconds a full-size step and a warm-up step took on that probe.
    #[serde(default)]
    pub probe_pace: Option<splat_train::schedule::Pace>,
    /// The mean seconds of the full-size and warm-up steps the run then took (all of them,
    /// the budget rounds' thrown-away branches too): what the probe's figures are compared with.
    #[serde(default)]
    pub run_pace: splat_train::schedule::Pace,
    /// The run's steps at the model size the probe timed (before a budget round or a
    /// refinement changed it): the like-for-like comparison with the probe. `None` when the
    /// run never trained that model in this session (a resumed run).
    #[serde(default)]
    pub probed_size_steps: Option<splat_train::SizedSteps>,
    /// Held-out scores before training (absent when training continued from a checkpoint made
    /// by an older version).
    pub step_zero: Option<StepZero>,
    /// Training curve.
    pub curve: Vec<CurvePoint>,
    /// Held-out scores during training, every `eval.every` steps (empty when 0).
    pub heldout_curve: Vec<HeldoutPoint>,
    /// The automatic splat budget's plan and rounds (no plan: it did not run).
    pub budget: splat_train::BudgetSearch,
    /// The tolerance the budget worked to (dB).
    pub budget_tolerance_db: f64,
    /// The SH degree and bands the budget kept after training (`None`: no budget).
    pub sh_bands: Option<splat_train::sh_bands::BandChoice>,
    /// Held-out metrics.
    pub metrics: Metrics,
    /// The model file written.
    pub model_path: PathBuf,
    /// Its size in bytes.
    pub model_bytes: u64,
    /// The other files of the same model (SPZ, glTF, `.splat`) and their sizes in bytes.
    pub compact_files: Vec<(PathBuf, u64)>,
    /// Times of this run's stages (init, train, write, eval).
    pub timings: Vec<StageTiming>,
}

/// Everything report.json holds.
#[derive(Debug, Clone, Serialize)]
pub struct Report {
    /// Version of the transcoder.
    pub version: String,
    /// The input.
    pub input: InputInfo,
    /// The configuration used.
    pub config: Config,
    /// Training views and held-out views.
    pub train_views: usize,
    /// Held-out views.
    pub heldout_views: usize,
    /// Shared stages (load, rig, render, dataset).
    pub timings: Vec<StageTiming>,
    /// Runs, the main one first.
    pub runs: Vec<RunReport>,
    /// Total wall time in seconds, of this session when the run was resumed.
    pub total_seconds: f64,
    /// Whether this session continued a killed run: its stages and total are this session's,
    /// while each model's training time spans every session.
    #[serde(default)]
    pub resumed: bool,
}

/// Pictures of one held-out view for the HTML page (images on black, clamped, 3·W·H).
#[derive(Debug, Clone)]
pub struct ViewPictures {
    /// View name.
    pub name: String,
    /// Width in pixels.
    pub width: u32,
    /// Height in pixels.
    pub height: u32,
    /// The reference.
    pub reference: Vec<f32>,
    /// Each run's render, in the order of `Report::runs`.
    pub renders: Vec<Vec<f32>>,
}

/// The interactive viewer's folder beside report.html (written by [`crate::viewer`]).
pub const VIEWER_DIR: &str = "viewer";

/// Absolute error (mean over channels) at which the heat map saturates.
pub const HEAT_MAX_ERROR: f32 = 0.25;

/// Writes `dir/report.json` and `dir/report.html` atomically; returns the HTML path.
pub fn write_report(dir: &Path, report: &Report, pictures: &[ViewPictures]) -> io::Result<PathBuf> {
    std::fs::create_dir_all(dir)?;
    let json = serde_json::to_vec_pretty(report).map_err(io::Error::other)?;
    write_atomic(&dir.join("report.json"), &json)?;
    let html = render_html(report, pictures)?;
    let path = dir.join("report.html");
    write_atomic(&path, html.as_bytes())?;
    Ok(path)
}

/// The HTML page.
pub fn render_html(report: &Report, pictures: &[ViewPictures]) -> io::Result<String> {
    let mut h = String::new();
    let names: Vec<String> = report
        .runs
        .iter()
        .map(|r| format!("{} init", r.init.mode))
        .collect();
    let _ = write!(
        h,
        "<!DOCTYPE html>\n<html lang=\"en\"><head><meta charset=\"utf-8\">\
         <title>transcode report: {}</title><style>{STYLE}</style></head><body>\n",
        esc(&report.input.path.display().to_string())
    );
    let _ = write!(
        h,
        "<h1>transcode report</h1>\n<p>Input <code>{}</code>: {} with {}, {} capture cameras, {}. \
         {} training views, {} held-out views. Total {:.1} s. transcode {}.</p>\n",
        esc(&report.input.path.display().to_string()),
        esc(&report.input.kind),
        if report.input.triangles > 0 {
            format!(
                "{} vertices and {} triangles",
                report.input.points, report.input.triangles
            )
        } else {
            format!("{} points", report.input.points)
        },
        report.input.capture_cameras,
        human_bytes(report.input.bytes),
        report.train_views,
        report.heldout_views,
        report.total_seconds,
        esc(&report.version),
    );
    h.push_str(&splat_viewer::report_section(VIEWER_DIR));
    metrics_table(&mut h, report, &names);
    breakdown_table(&mut h, report, &names);
    budget::section(&mut h, &report.runs, &names);
    timings_table(&mut h, report, &names);
    h.push_str(&format!(
        "<h2>Training PSNR against wall time</h2>\n<p>PSNR of the training view of each logged \
         step, as a moving mean over {CURVE_WINDOW} log points (single views vary a lot); circles: \
         held-out PSNR on black at step 0 (before any training step) and at the end; dashed: \
         held-out PSNR on black during training, when the run scored it (<code>eval.every</code>, \
         <code>--eval-every</code>).</p>\n"
    ));
    h.push_str(&curve_svg(report, &names));
    h.push_str(&format!(
        "<h2>Held-out views</h2>\n<p>Reference | splats | error heat map (mean absolute error over \
         channels, black = 0, white = {HEAT_MAX_ERROR} or more), on a black background.</p>\n"
    ));
    for p in pictures {
        let _ = write!(h, "<h3>{}</h3>\n<div class=\"row\">", esc(&p.name));
        figure(
            &mut h,
            "reference",
            &png_data_uri(&p.reference, p.width, p.height)?,
        );
        for (render, name) in p.renders.iter().zip(&names) {
            figure(
                &mut h,
                &format!("splats ({name})"),
                &png_data_uri(render, p.width, p.height)?,
            );
            let heat = heat_map(&p.reference, render);
            figure(
                &mut h,
                &format!("error ({name})"),
                &png_data_uri(&heat, p.width, p.height)?,
            );
        }
        h.push_str("</div>\n");
    }
    h.push_str("</body></html>\n");
    Ok(h)
}

const STYLE: &str = "body{font-family:sans-serif;margin:2em;max-width:1400px}\
table{border-collapse:collapse;margin:1em 0}td,th{border:1px solid #bbb;padding:4px 10px;text-align:right}\
th:first-child,td:first-child{text-align:left}.row{display:flex;flex-wrap:wrap;gap:8px}\
figure{margin:0}figcaption{text-align:center;font-size:90%}img{image-rendering:pixelated;max-width:320px}";

fn figure(h: &mut String, caption: &str, uri: &str) {
    let _ = write!(
        h,
        "<figure><img src=\"{uri}\" alt=\"{c}\"><figcaption>{c}</figcaption></figure>",
        c = esc(caption)
    );
}

fn metrics_table(h: &mut String, report: &Report, names: &[String]) {
    h.push_str("<h2>Metrics on held-out views</h2>\n<table><tr><th>metric</th>");
    for n in names {
        let _ = write!(h, "<th>{}</th>", esc(n));
    }
    h.push_str("</tr>\n");
    type Row = (&'static str, fn(&RunReport) -> String);
    let rows: [Row; 24] = [
        ("PSNR, black background (dB)", |r| {
            format!("{:.2}", r.metrics.psnr_black)
        }),
        ("PSNR, white background (dB)", |r| {
            format!("{:.2}", r.metrics.psnr_white)
        }),
        ("masked PSNR (object only), black / white (dB)", |r| {
            format!(
                "{:.2} / {:.2}",
                r.metrics.masked_psnr_black, r.metrics.masked_psnr_white
            )
        }),
        ("step 0, initial fit: PSNR black / white (dB)", |r| {
            r.step_zero.as_ref().map_or("–".into(), |z| {
                format!("{:.2} / {:.2}", z.fit.psnr_black, z.fit.psnr_white)
            })
        }),
        (
            "step 0, after the colour solve: PSNR black / white (dB)",
            |r| {
                r.step_zero
                    .as_ref()
                    .and_then(|z| z.solved)
                    .map_or("–".into(), |s| {
                        format!("{:.2} / {:.2}", s.psnr_black, s.psnr_white)
                    })
            },
        ),
        ("colour solve: iterations, seconds", |r| {
            r.step_zero
                .as_ref()
                .and_then(|z| z.solve.as_ref().map(|s| (s.iterations, z.solve_seconds)))
                .map_or("–".into(), |(i, t)| format!("{i}, {t:.1}"))
        }),
        ("SSIM, black", |r| format!("{:.4}", r.metrics.ssim_black)),
        ("SSIM, white", |r| format!("{:.4}", r.metrics.ssim_white)),
        ("alpha IoU", |r| format!("{:.4}", r.metrics.alpha_iou)),
        ("holes: missing alpha inside the mask", |r| {
            format!("{:.4}", r.metrics.hole_alpha)
        }),
        ("free-space alpha outside the mask", |r| {
            format!("{:.4}", r.metrics.free_alpha)
        }),
        ("splats", |r| r.metrics.splats.to_string()),
        ("SH degree", |r| r.init.sh_degree.to_string()),
        ("distance to surface, mean (spacings)", |r| {
            surface(r, |s| s.mean / s.spacing.max(f64::MIN_POSITIVE))
        }),
        ("distance to surface, 95th pct (spacings)", |r| {
            surface(r, |s| s.p95 / s.spacing.max(f64::MIN_POSITIVE))
        }),
        ("splats beyond the threshold (count, opacity share)", |r| {
            surface_text(r, |s| count_and_share(s.far, s.far_share))
        }),
        ("of them inside the object", |r| {
            surface_text(r, |s| {
                if s.oriented {
                    count_and_share(s.interior, s.interior_share)
                } else {
                    "– (no normals)".into()
                }
            })
        }),
        ("of them floaters (out of 3σ reach of the surface)", |r| {
            surface_text(r, |s| count_and_share(s.floaters, s.floater_share))
        }),
        ("iterations", |r| r.iterations.to_string()),
        ("training time (s)", |r| format!("{:.1}", r.train_seconds)),
        ("step time, probe / run (ms)", step_time_cell),
        ("model file", |r| human_bytes(r.model_bytes)),
        ("compact files", compact_files_cell),
        ("SH fit RMS, degree 0/1/2/3", |r| {
            r.init.sh_fit_rms.map_or("–".into(), |e| {
                format!("{:.4} / {:.4} / {:.4} / {:.4}", e[0], e[1], e[2], e[3])
            })
        }),
    ];
    for (label, f) in rows {
        let _ = write!(h, "<tr><td>{label}</td>");
        for r in &report.runs {
            let _ = write!(h, "<td>{}</td>", esc(&f(r)));
        }
        h.push_str("</tr>\n");
    }
    h.push_str("</table>\n");
}

/// The time-budget probe's step times against the run's, full size and warm-up, each with
/// its error, and against the run's steps at the probe's splat count where there were some.
fn step_time_cell(r: &RunReport) -> String {
    let Some(probe) = r.probe_pace else {
        return "–".into();
    };
    let at_size = r.probed_size_steps.map(|s| (s.splats, s.mean_pace()));
    let kinds = [
        (
            "full size",
            probe.step_s,
            r.run_pace.step_s,
            at_size.and_then(|(n, p)| Some((n, p.step_s?))),
        ),
        (
            "warm-up",
            probe.coarse_step_s,
            r.run_pace.coarse_step_s,
            at_size.and_then(|(n, p)| Some((n, p.coarse_step_s?))),
        ),
    ];
    let off = |p: f64, run: f64| 100.0 * (p / run - 1.0);
    let shown: Vec<String> = kinds
        .iter()
        .filter_map(|&(kind, p, run, same_size)| {
            let (p, run) = (p?, run?);
            let like_for_like = same_size.map_or(String::new(), |(n, s)| {
                format!(
                    "; at the probe's {n} splats {:.1}, {:+.0} %",
                    1e3 * s,
                    off(p, s)
                )
            });
            Some(format!(
                "{kind} {:.1} / {:.1} ({:+.0} %{like_for_like})",
                1e3 * p,
                1e3 * run,
                off(p, run)
            ))
        })
        .collect();
    if shown.is_empty() {
        "–".into()
    } else {
        shown.join("; ")
    }
}

/// The compact files written beside the model, by extension and size.
fn compact_files_cell(r: &RunReport) -> String {
    if r.compact_files.is_empty() {
        return "–".into();
    }
    r.compact_files
        .iter()
        .map(|(p, bytes)| {
            let ext = p
                .extension()
                .map_or(String::new(), |e| e.to_string_lossy().into());
            format!("{ext} {}", human_bytes(*bytes))
        })
        .collect::<Vec<_>>()
        .join(", ")
}

/// Where the held-out error comes from: each region's share of the MSE on black and on white,
/// and the part of it that is coverage error (`splat_train::eval::breakdown`).
fn breakdown_table(h: &mut String, report: &Report, names: &[String]) {
    h.push_str(
        "<h2>Where the held-out error comes from</h2>\n<p>Pixels by the reference's coverage in \
         their 3×3 neighbourhood. Each cell is the region's contribution to the image MSE \
         (×10⁻⁴; the regions add up to the whole). On white the error is colour minus coverage \
         error, so a gap between the backgrounds that sits in the silhouette's alpha column is \
         edge coverage, not colour.</p>\n<table><tr><th>run</th><th>region</th><th>pixels \
         (all views)</th><th>MSE black</th><th>MSE white</th><th>alpha error²</th><th>alpha \
         bias</th></tr>\n",
    );
    for (r, n) in report.runs.iter().zip(names) {
        for (region, e) in r.metrics.breakdown.regions() {
            let _ = writeln!(
                h,
                "<tr><td>{}</td><td>{region}</td><td>{}</td><td>{:.3}</td><td>{:.3}</td>\
                 <td>{:.3}</td><td>{:+.3}</td></tr>",
                esc(n),
                e.pixels,
                1e4 * e.mse_black,
                1e4 * e.mse_white,
                1e4 * e.mse_alpha,
                1e4 * e.alpha_bias
            );
        }
    }
    h.push_str("</table>\n");
}

fn surface(r: &RunReport, f: fn(&splat_train::eval::SurfaceDistance) -> f64) -> String {
    r.metrics
        .surface
        .as_ref()
        .map_or("–".into(), |s| format!("{:.3}", f(s)))
}

/// A cell from the run's surface distance ("–" without one).
fn surface_text(r: &RunReport, f: fn(&splat_train::eval::SurfaceDistance) -> String) -> String {
    r.metrics.surface.as_ref().map_or("–".into(), f)
}

/// A count of splats and their share of the opacity.
fn count_and_share(count: usize, share: f64) -> String {
    format!("{count} ({:.1} %)", 100.0 * share)
}

fn timings_table(h: &mut String, report: &Report, names: &[String]) {
    h.push_str("<h2>Time per stage</h2>\n<table><tr><th>stage</th><th>seconds</th></tr>\n");
    for t in &report.timings {
        let _ = writeln!(
            h,
            "<tr><td>{}</td><td>{:.2}</td></tr>",
            esc(&t.stage),
            t.seconds
        );
    }
    for (r, n) in report.runs.iter().zip(names) {
        for t in &r.timings {
            let _ = writeln!(
                h,
                "<tr><td>{} ({})</td><td>{:.2}</td></tr>",
                esc(&t.stage),
                esc(n),
                t.seconds
            );
        }
    }
    let _ = writeln!(
        h,
        "<tr><th>total{}</th><th>{:.2}</th></tr></table>",
        if report.resumed {
            " (this session: the run was resumed, and a model's training time spans every \
             session)"
        } else {
            ""
        },
        report.total_seconds
    );
}

/// Log points averaged in the plotted training curve.
pub const CURVE_WINDOW: usize = 5;

/// Moving mean of the finite PSNRs of a curve over [`CURVE_WINDOW`] points: (elapsed, PSNR).
#[must_use]
pub fn smoothed(curve: &[CurvePoint]) -> Vec<(f64, f64)> {
    let pts: Vec<&CurvePoint> = curve.iter().filter(|p| p.psnr.is_finite()).collect();
    (0..pts.len())
        .map(|i| {
            let lo = i.saturating_sub(CURVE_WINDOW - 1);
            let win = &pts[lo..=i];
            let mean = win.iter().map(|p| p.psnr).sum::<f64>() / win.len() as f64;
            (pts[i].elapsed_s, mean)
        })
        .collect()
}

/// The training curves as an inline SVG line plot: each run's smoothed training PSNR (solid),
/// its held-out curve (dashed) and its held-out markers.
fn curve_svg(report: &Report, names: &[String]) -> String {
    let mut series = Vec::new();
    let mut markers = Vec::new();
    for (i, (r, name)) in report.runs.iter().zip(names).enumerate() {
        let colour = plot::COLOURS[i % plot::COLOURS.len()];
        series.push(plot::Series {
            label: name.clone(),
            title: format!("{name}: training PSNR"),
            colour,
            dashed: false,
            points: smoothed(&r.curve),
        });
        if !r.heldout_curve.is_empty() {
            series.push(plot::Series {
                label: String::new(),
                title: "held-out PSNR on black".into(),
                colour,
                dashed: true,
                points: r
                    .heldout_curve
                    .iter()
                    .map(|p| (p.elapsed_s, p.score.psnr_black))
                    .collect(),
            });
        }
        markers.extend(
            heldout_markers(r)
                .into_iter()
                .map(|(t, p, label)| (t, p, label.to_string(), colour)),
        );
    }
    if series.iter().all(|s| s.points.is_empty()) && markers.is_empty() {
        return "<p>(no training history)</p>\n".into();
    }
    plot::svg(
        &plot::Axes {
            x_label: "wall time of training (s)".into(),
            y_label: "PSNR (dB)".into(),
            round_y: true,
            integer_x: false,
        },
        &series,
        &markers,
    )
}

/// Held-out PSNRs on black of a run as (time, PSNR, label): at step 0 (the initial fit, and the
/// colour solve when it ran) and at the end of training.
fn heldout_markers(r: &RunReport) -> Vec<(f64, f64, &'static str)> {
    let mut m = Vec::new();
    if let Some(z) = &r.step_zero {
        m.push((0.0, z.fit.psnr_black, "held-out, step 0 (fit)"));
        if let Some(s) = z.solved {
            m.push((0.0, s.psnr_black, "held-out, step 0 (solve)"));
        }
    }
    if r.metrics.psnr_black.is_finite() {
        m.push((r.train_seconds, r.metrics.psnr_black, "held-out, end"));
    }
    m
}

/// Per-pixel error heat map (RGB): mean absolute error over channels through a black–red–yellow–white ramp.
#[must_use]
pub fn heat_map(reference: &[f32], render: &[f32]) -> Vec<f32> {
    reference
        .chunks_exact(3)
        .zip(render.chunks_exact(3))
        .flat_map(|(a, b)| {
            let e = ((a[0] - b[0]).abs() + (a[1] - b[1]).abs() + (a[2] - b[2]).abs()) / 3.0;
            let t = (e / HEAT_MAX_ERROR).clamp(0.0, 1.0) * 3.0;
            [
                t.min(1.0),
                (t - 1.0).clamp(0.0, 1.0),
                (t - 2.0).clamp(0.0, 1.0),
            ]
        })
        .collect()
}

/// An RGB image in [0, 1] as an 8-bit PNG data URI.
pub fn png_data_uri(rgb: &[f32], width: u32, height: u32) -> io::Result<String> {
    Ok(format!(
        "data:image/png;base64,{}",
        base64(&png_bytes(rgb, width, height)?)
    ))
}

/// An RGB image in [0, 1] as 8-bit PNG bytes.
pub fn png_bytes(rgb: &[f32], width: u32, height: u32) -> io::Result<Vec<u8>> {
    let bytes: Vec<u8> = rgb
        .iter()
        .map(|v| (v.clamp(0.0, 1.0) * 255.0).round() as u8)
        .collect();
    let img = image::RgbImage::from_raw(width, height, bytes)
        .ok_or_else(|| io::Error::other("image buffer does not match its size"))?;
    let mut png = io::Cursor::new(Vec::new());
    img.write_to(&mut png, image::ImageFormat::Png)
        .map_err(io::Error::other)?;
    Ok(png.into_inner())
}

/// Standard base64 (RFC 4648 §4) with padding.
#[must_use]
pub fn base64(data: &[u8]) -> String {
    const ALPHABET: &[u8; 64] = b"ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
    let mut out = String::with_capacity(data.len().div_ceil(3) * 4);
    for chunk in data.chunks(3) {
        let b = [
            chunk[0],
            chunk.get(1).copied().unwrap_or(0),
            chunk.get(2).copied().unwrap_or(0),
        ];
        let n = (u32::from(b[0]) << 16) | (u32::from(b[1]) << 8) | u32::from(b[2]);
        for k in 0..4 {
            if k <= chunk.len() {
                out.push(ALPHABET[((n >> (18 - 6 * k)) & 63) as usize] as char);
            } else {
                out.push('=');
            }
        }
    }
    out
}

/// Bytes in B, KiB, MiB or GiB.
pub fn human_bytes(b: u64) -> String {
    let b = b as f64;
    if b < 1024.0 {
        format!("{b} B")
    } else if b < 1024.0 * 1024.0 {
        format!("{:.1} KiB", b / 1024.0)
    } else if b < 1024.0 * 1024.0 * 1024.0 {
        format!("{:.1} MiB", b / (1024.0 * 1024.0))
    } else {
        format!("{:.2} GiB", b / (1024.0 * 1024.0 * 1024.0))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn base64_matches_rfc4648_vectors() {
        for (input, want) in [
            ("", ""),
            ("f", "Zg=="),
            ("fo", "Zm8="),
            ("foo", "Zm9v"),
            ("foob", "Zm9vYg=="),
            ("fooba", "Zm9vYmE="),
            ("foobar", "Zm9vYmFy"),
        ] {
            assert_eq!(base64(input.as_bytes()), want);
        }
    }

    #[test]
    fn png_data_uri_decodes_back() {
        let rgb = vec![0.0, 0.5, 1.0, 1.0, 0.0, 0.25];
        let uri = png_data_uri(&rgb, 2, 1).unwrap();
        assert!(uri.starts_with("data:image/png;base64,iVBORw0KGgo"));
    }

    #[test]
    fn smoothing_is_a_trailing_mean() {
        let curve: Vec<CurvePoint> = (0..7)
            .map(|i| CurvePoint {
                iteration: i,
                elapsed_s: f64::from(i),
                psnr: if i == 3 { f64::INFINITY } else { f64::from(i) },
                splats: 1,
            })
            .collect();
        let s = smoothed(&curve);
        assert_eq!(s.len(), 6);
        assert_eq!(s[0], (0.0, 0.0));
        assert_eq!(s[5], (6.0, (6.0 + 5.0 + 4.0 + 2.0 + 1.0) / 5.0));
    }

    #[test]
    fn heat_map_ramp() {
        let h = heat_map(
            &[0.0, 0.0, 0.0, 1.0, 1.0, 1.0],
            &[0.0, 0.0, 0.0, 0.0, 0.0, 0.0],
        );
        assert_eq!(&h[..3], &[0.0, 0.0, 0.0]);
        assert_eq!(&h[3..], &[1.0, 1.0, 1.0]);
    }
}
