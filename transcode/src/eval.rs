//! Evaluation policy: how the configuration's `[eval]` table sets the evaluator's options.
//!
//! The evaluator itself (metrics on black and white, coverage, distance to the surface) is
//! [`splat_train::eval`]; `transcode eval` and the pipeline both call it with these options.

use splat_train::eval::EvalOptions;

impl From<&crate::config::EvalConfig> for EvalOptions {
    fn from(c: &crate::config::EvalConfig) -> Self {
        Self {
            alpha_threshold: c.alpha_threshold,
            floater_spacings: c.floater_spacings,
        }
    }
}
