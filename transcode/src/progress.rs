//! What a long run tells its caller while it works.
//!
//! The library never prints: [`crate::pipeline`] hands [`Event`]s to an observer the caller
//! chooses (the `transcode` binary draws them as lines and progress bars on stderr; tests and
//! other programs can ignore them, log them or show them their own way).

/// One thing the pipeline reports.
#[derive(Debug, Clone, PartialEq)]
pub enum Event {
    /// A stage begins: stage `index` of `of` (1-based), described by `what`.
    Stage {
        /// Which stage, from 1.
        index: u32,
        /// How many stages a run has.
        of: u32,
        /// What the stage does, e.g. "loading input.ply".
        what: String,
    },
    /// A detail of the current stage.
    Note(String),
    /// A sequence's frame begins: frame `index` of `of` (1-based), named `name`; `what` says
    /// how it starts.
    Frame {
        /// Which frame, from 1, in the whole sequence.
        index: usize,
        /// Frames in the sequence.
        of: usize,
        /// The frame's name.
        name: String,
        /// How it starts ("cold start", "warm start from …").
        what: String,
    },
    /// A counted task begins: `total` `unit`s ("views", "steps"), `done` of them already done.
    Begin {
        /// What is counted.
        unit: &'static str,
        /// How many there are.
        total: u64,
        /// How many were done before (a resumed run).
        done: u64,
    },
    /// The counted task's total is now `0`: a time-budgeted run re-estimates how many steps fit.
    Total(u64),
    /// The counted task has done `done`; `message` carries news (training PSNR, splats).
    Advance {
        /// How many are done.
        done: u64,
        /// A short status, when there is one.
        message: Option<String>,
    },
    /// The counted task ended.
    End,
}

/// Receives the pipeline's [`Event`]s; called from the thread doing the work, and from worker
/// threads while views render, hence `Sync`.
pub type Observer<'a> = &'a (dyn Fn(Event) + Sync);

/// An observer that ignores everything.
pub fn ignore(_: Event) {}
