//! The automatic splat budget as a run drives it: its rounds, what the log says of each, and
//! the SH bands chosen at the end.

use splat_core::Splats;
use splat_train::eval::EvalOptions;
use splat_train::{BudgetConfig, BudgetSearch, Trainer, View};

use super::error::PipelineError;
use super::references::References;
use crate::config::Config;
use crate::progress::{Event, Observer};

/// The automatic splat budget's search while a model trains, and its settings.
pub(super) struct Budgeting<'a> {
    pub(super) search: &'a mut BudgetSearch,
    pub(super) config: &'a BudgetConfig,
}

/// Stage 4 (end), with the splat budget: the SH degree and per-splat bands the held-out views
/// need ([`splat_train::sh_bands::choose_bands`]), within what the budget's rounds left of its
/// tolerance.
pub(super) fn choose_bands(
    splats: Splats,
    search: &BudgetSearch,
    refs: &References,
    cfg: &Config,
    observer: Observer<'_>,
) -> Result<(Splats, splat_train::sh_bands::BandChoice), PipelineError> {
    let b = &cfg.budget;
    let tolerance = b
        .bands_tolerance_db
        .min(search.left_db(b.tolerance_db).max(0.0));
    let options = cfg.eval_options();
    // One render a view, as the budget's rounds score: the full evaluation adds a second render,
    // the SSIMs and the error breakdown to each view, none of which the choice reads.
    let mut psnr = |s: &Splats| -> Result<f64, PipelineError> {
        let (black, white) = splat_train::psnr_black_and_white(s, &refs.heldout, &options)?;
        Ok(splat_train::psnr_both(black, white))
    };
    let (splats, choice) =
        splat_train::sh_bands::choose_bands(&splats, tolerance, b.static_sh_rms, &mut psnr)?;
    observer(Event::Note(format!(
        "SH bands: degree {} kept of {} (held-out PSNR by degree: {}); {} splats without view \
         dependence lost their higher bands",
        choice.degree,
        choice.trained_degree,
        choice
            .psnr_by_degree
            .iter()
            .map(|p| format!("{p:.2}"))
            .collect::<Vec<_>>()
            .join(", "),
        choice.flattened
    )));
    Ok((splats, choice))
}

/// Runs the splat budget's due round: both branches, scored on the held-out views on black and
/// on white ([`splat_train::BudgetRound::drop_db`] takes the worse).
pub(super) fn budget_round(
    trainer: &mut Trainer,
    budget: &mut Budgeting<'_>,
    heldout: &[View],
    options: &EvalOptions,
    advance: &mut dyn FnMut(&splat_train::Progress),
    observer: Observer<'_>,
) -> Result<(), PipelineError> {
    let mut heldout_psnr = |s: &Splats| -> Result<splat_train::HeldoutPsnr, PipelineError> {
        let (black, white) = splat_train::psnr_black_and_white(s, heldout, options)?;
        Ok(splat_train::HeldoutPsnr { black, white })
    };
    let (due_at, n) = (trainer.iteration(), trainer.splats().len());
    let round = budget
        .search
        .run_round(trainer, budget.config, &mut heldout_psnr, advance)?;
    for skip in budget
        .search
        .skipped
        .iter()
        .filter(|s| s.iteration == due_at)
    {
        let why = if skip.floor_db > skip.left_db {
            format!("it could not cost less than {:.3} dB", skip.floor_db)
        } else {
            format!(
                "its first look could not cost less than {:.3} dB, too much to be looked at again",
                skip.first_look_floor_db
            )
        };
        observer(Event::Note(format!(
            "splat budget, step {due_at}: a merge keeping {:.1} % of {n} splats skipped: {why}, \
             and {:.3} dB of the tolerance is left",
            100.0 * skip.keep,
            skip.left_db
        )));
    }
    let Some(round) = round else {
        let why = if budget.search.no_time_left {
            "too little of the time budget is left for a round's two branches; the search ends"
        } else if budget
            .search
            .skipped
            .last()
            .is_some_and(|s| s.iteration == due_at)
        {
            "no merge left that could cost less than what is left of the tolerance; the search ends"
        } else {
            "nothing left to merge"
        };
        observer(Event::Note(format!(
            "splat budget, step {}: {why} at {} splats",
            trainer.iteration(),
            trainer.splats().len()
        )));
        return Ok(());
    };
    let cost = match (round.pruned_psnr, round.drop_db()) {
        (Some(p), Some(d)) => format!(
            "costs {d:+.3} dB held-out{}, the worse of black ({p:.2} against {:.2}) and white \
             ({:.2} against {:.2})",
            match (round.first_look_db, round.second_look_db) {
                (Some(f), Some(second)) => format!(
                    " with both branches trained to the end of the run (the first look \
                     {f:+.3}, the second {second:+.3})"
                ),
                (Some(f), None) =>
                    format!(" after a second trial of both branches (the first {f:+.3})"),
                _ => String::new(),
            },
            round.kept_psnr,
            round.pruned_psnr_white.unwrap_or(f64::NAN),
            round.kept_psnr_white.unwrap_or(f64::NAN),
        ),
        _ => "not measured".into(),
    };
    let left = budget.search.left_db(budget.config.tolerance_db);
    observer(Event::Note(format!(
        "splat budget, step {}: {} → {} splats {cost}; {} ({:.1} s)",
        round.iteration,
        round.splats,
        round.candidate,
        if round.out_of_time {
            "out of time, kept the whole model".into()
        } else if round.accepted && budget.search.tolerance_spent {
            "merged; too little of the tolerance is left for another round, the search ends".into()
        } else if round.accepted {
            format!("merged, {left:.3} dB of the tolerance left")
        } else if budget.search.finished() {
            "over the tolerance, kept the whole model; the search ends".into()
        } else {
            "over the tolerance, kept the whole model; the next round merges fewer".into()
        },
        round.seconds.total(),
    )));
    Ok(())
}
