//! The report's splat-budget section: what each round of the automatic budget measured, as a
//! rate–distortion plot (held-out PSNR against splat count and file size) with the chosen model
//! marked, and a table.

use std::fmt::Write as _;

use splat_train::BudgetRound;

use super::{RunReport, human_bytes};
use crate::plot::{self, esc};

/// Bytes a model of `splats` splats would take at `run`'s measured bytes per splat of `file`
/// (`bytes` for `splats_then` splats): files of one SH degree grow linearly with the count.
fn scaled(bytes: u64, splats_then: usize, splats: usize) -> u64 {
    if splats_then == 0 {
        return 0;
    }
    (bytes as f64 * splats as f64 / splats_then as f64).round() as u64
}

/// The SPZ file of `run`, if it wrote one: its size in bytes.
fn spz_bytes(run: &RunReport) -> Option<u64> {
    run.compact_files
        .iter()
        .find(|(p, _)| p.extension().is_some_and(|e| e.eq_ignore_ascii_case("spz")))
        .map(|&(_, b)| b)
}

/// Appends the section for the runs that searched a budget; nothing when none did.
pub(super) fn section(h: &mut String, runs: &[RunReport], names: &[String]) {
    let searched: Vec<(&RunReport, &String)> = runs
        .iter()
        .zip(names)
        .filter(|(r, _)| r.budget.plan.is_some())
        .collect();
    if searched.is_empty() {
        return;
    }
    h.push_str(
        "<h2>Splat budget: held-out PSNR against splats and size</h2>\n<p>Each round trains \
         the model two ways from the same step: whole (the control) and with its cheapest cells \
         merged, and scores both on the held-out views on black and on white at the same four \
         steps over the last quarter of the trial (the same times where a time budget binds the \
         schedule), taking the means; a round costs what the worse background lost. A pruned \
         branch is kept while \
         the rounds' costs add up to no more than the tolerance \
         (<code>budget.tolerance_db</code>, <code>--budget-tolerance</code>). A round refused at \
         up to <code>budget.second_look_within</code> times what is left is looked at again \
         after both branches train <code>budget.second_look_trials</code> trials more (the \
         merged branch is still recovering from its merges), where the rounds' steps leave room, \
         and decided on that (the table gives both looks' costs); after a refused \
         round the next one merges half as many splats, and the third refusal ends the search, \
         as does a tolerance spent to within <code>budget.least_left_db</code>. A merge that \
         cannot cost less than what is left is not tried and counts as refused: one as large as \
         an accepted merge costs at least what that one did, and a gentler one after a refusal \
         at least a quarter of the refused one's cost. \
         Lines join each round's two branches (solid: kept, \
         dashed: refused); the circle is the chosen model after all its training. Sizes of the \
         branches are the final model's files scaled by splat count.</p>\n",
    );
    let mut series = Vec::new();
    let mut markers = Vec::new();
    for (i, (run, name)) in searched.iter().enumerate() {
        let colour = plot::COLOURS[i % plot::COLOURS.len()];
        for r in &run.budget.rounds {
            let (Some(pruned), Some(cost)) = (r.pruned_psnr, r.drop_db()) else {
                continue;
            };
            series.push(plot::Series {
                label: String::new(),
                title: format!(
                    "{name}: step {}, {} → {} splats, {:+.3} dB",
                    r.iteration, r.splats, r.candidate, -cost
                ),
                colour,
                dashed: !r.accepted,
                points: vec![(r.splats as f64, r.kept_psnr), (r.candidate as f64, pruned)],
            });
        }
        let n = run.metrics.splats;
        let size = spz_bytes(run).map_or_else(
            || format!("PLY {}", human_bytes(run.model_bytes)),
            |b| format!("SPZ {}", human_bytes(b)),
        );
        markers.push((
            n as f64,
            run.metrics.psnr_black,
            format!("{name}: {n} splats, {size}"),
            colour,
        ));
    }
    h.push_str(&plot::svg(
        &plot::Axes {
            x_label: "splats".into(),
            y_label: "held-out PSNR on black (dB)".into(),
            round_y: true,
            integer_x: false,
        },
        &series,
        &markers,
    ));
    for (run, name) in searched {
        table(h, run, name);
    }
}

fn table(h: &mut String, run: &RunReport, name: &str) {
    let spz = spz_bytes(run);
    let n = run.metrics.splats;
    let _ = write!(
        h,
        "<h3>{}</h3>\n<p>Initial splats: {}; chosen: {} ({:.1} % of them), {} in the rounds \
         (tolerance {:.2} dB).</p>\n",
        esc(name),
        run.init.splats,
        n,
        100.0 * n as f64 / run.init.splats.max(1) as f64,
        spent_words(run.budget.spent_db()),
        run.budget_tolerance_db,
    );
    if let Some(b) = &run.sh_bands {
        let _ = writeln!(
            h,
            "<p>SH bands after training: degree {} kept of {} (held-out PSNR on black and white by degree: \
             {} dB); {} splats without view dependence lost their higher bands ({:.2} dB with \
             them dropped).</p>",
            b.degree,
            b.trained_degree,
            b.psnr_by_degree
                .iter()
                .map(|p| format!("{p:.2}"))
                .collect::<Vec<_>>()
                .join(" / "),
            b.flattened,
            b.psnr_flattened,
        );
    }
    h.push_str(
        "<table><tr><th>step</th><th>splats</th><th>merged to</th><th>control PSNR, black / white (dB)</th><th>merged PSNR, black / white (dB)</th><th>cost (dB)</th>\
         <th>steps of the merged branch</th><th>PLY / SPZ of the merged size</th>\
         <th>decision</th><th>time (s): planning, control, merged, scoring</th></tr>\n",
    );
    for r in &run.budget.rounds {
        let sizes = format!(
            "{} / {}",
            human_bytes(scaled(run.model_bytes, n, r.candidate)),
            spz.map_or("–".into(), |b| human_bytes(scaled(b, n, r.candidate)))
        );
        let decision = if r.out_of_time {
            "out of time"
        } else if r.accepted {
            "merged"
        } else {
            "refused: over the tolerance"
        };
        let _ = writeln!(
            h,
            "<tr><td>{}</td><td>{}</td><td>{}</td><td>{:.2} / {}</td><td>{} / {}</td><td>{}</td>\
             <td>{}</td><td>{sizes}</td><td>{decision}</td><td>{}</td></tr>",
            r.iteration,
            r.splats,
            r.candidate,
            r.kept_psnr,
            r.kept_psnr_white.map_or("–".into(), |p| format!("{p:.2}")),
            r.pruned_psnr.map_or("–".into(), |p| format!("{p:.2}")),
            r.pruned_psnr_white
                .map_or("–".into(), |p| format!("{p:.2}")),
            match (r.drop_db(), r.first_look_db, r.second_look_db) {
                (Some(d), Some(f), Some(second)) =>
                    format!("{d:+.3} at the run's end (first look {f:+.3}, second {second:+.3})"),
                (Some(d), Some(f), None) => format!("{d:+.3} (first look {f:+.3})"),
                (Some(d), None, _) => format!("{d:+.3}"),
                (None, ..) => "–".into(),
            },
            r.steps_pruned,
            round_seconds(r),
        );
    }
    let m = &run.metrics;
    let _ = writeln!(
        h,
        "<tr><th>chosen, trained to the end</th><td>{n}</td><td></td><td colspan=\"2\">black \
         {:.2}, white {:.2}, masked {:.2} / {:.2}</td><td></td><td></td><td>{} / {}</td><td></td>\
         <td></td></tr></table>",
        m.psnr_black,
        m.psnr_white,
        m.masked_psnr_black,
        m.masked_psnr_white,
        human_bytes(run.model_bytes),
        spz.map_or("–".into(), human_bytes),
    );
    if let Some(time) = rounds_time(&run.budget.rounds) {
        let _ = writeln!(h, "<p>{time}</p>");
    }
    if !run.budget.skipped.is_empty() {
        let skipped: Vec<String> = run
            .budget
            .skipped
            .iter()
            .map(|s| {
                format!(
                    "step {}, keeping {:.1} % (at least {:.3} dB, at its first look {:.3}; \
                     {:.3} dB left)",
                    s.iteration,
                    100.0 * s.keep,
                    s.floor_db,
                    s.first_look_floor_db.max(s.floor_db),
                    s.left_db
                )
            })
            .collect();
        let _ = writeln!(
            h,
            "<p>Merges not tried, as they could not cost less than what was left of the \
             tolerance, or their first look could not cost little enough to be looked at again \
             (<code>budget.skip_hopeless</code>), each counted as refused: {}.</p>",
            skipped.join("; ")
        );
    }
}

/// A round's time cell: "–" for rounds saved before their time was measured.
fn round_seconds(r: &BudgetRound) -> String {
    let t = &r.seconds;
    if t.total() <= 0.0 {
        return "–".into();
    }
    format!(
        "{:.1}: {:.1}, {:.1}, {:.1}, {:.1}",
        t.total(),
        t.planning,
        t.control,
        t.merged,
        t.scoring
    )
}

/// The sentence on what the rounds cost in time, or nothing when none was measured.
fn rounds_time(rounds: &[BudgetRound]) -> Option<String> {
    let total: f64 = rounds.iter().map(|r| r.seconds.total()).sum();
    if total <= 0.0 {
        return None;
    }
    let sum = |f: fn(&BudgetRound) -> f64| -> f64 { rounds.iter().map(f).sum() };
    Some(format!(
        "The rounds took {:.1} s: {:.1} s scoring the splats' contributions and merging, {:.1} s \
         scoring the branches on the held-out views, and {:.1} s training the branches that \
         were thrown away.",
        total,
        sum(|r| r.seconds.planning),
        sum(|r| r.seconds.scoring),
        sum(BudgetRound::discarded_seconds),
    ))
}

/// The rounds' total cost in words: a search whose rounds gained overall is not said to cost.
fn spent_words(spent_db: f64) -> String {
    if spent_db < 0.0 {
        format!("gaining {:.3} dB", -spent_db)
    } else {
        format!("costing {spent_db:.3} dB")
    }
}
