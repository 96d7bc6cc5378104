//! Which block of frames one task of a cluster job takes: `--shard I/N`, or the index and count
//! a Slurm job array or a Kubernetes Indexed Job gives its tasks.

use std::fmt;
use std::ops::Range;

use serde::{Deserialize, Serialize};

use super::SequenceError;

/// Shard `index` of `count` (0-based): the `index`-th of `count` contiguous blocks of frames.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub struct Shard {
    /// 0-based.
    pub index: usize,
    /// At least 1.
    pub count: usize,
}

impl Default for Shard {
    fn default() -> Self {
        Self { index: 0, count: 1 }
    }
}

impl fmt::Display for Shard {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}/{}", self.index, self.count)
    }
}

impl Shard {
    /// A shard, checked: `count` ≥ 1 and `index` < `count`.
    pub fn new(index: usize, count: usize) -> Result<Self, SequenceError> {
        if count == 0 || index >= count {
            return Err(SequenceError::Shard(format!(
                "shard {index}/{count}: the index must be below the count (0-based) and the count \
                 at least 1"
            )));
        }
        Ok(Self { index, count })
    }

    /// Parses `I/N`.
    pub fn parse(text: &str) -> Result<Self, SequenceError> {
        let bad = || {
            SequenceError::Shard(format!(
                "--shard {text}: expected I/N with 0 ≤ I < N, e.g. 0/4"
            ))
        };
        let (i, n) = text.split_once('/').ok_or_else(bad)?;
        let index = i.trim().parse().map_err(|_| bad())?;
        let count = n.trim().parse().map_err(|_| bad())?;
        Self::new(index, count)
    }

    /// The shard a cluster engine gives this task through the environment (`var` looks a
    /// variable up): a Slurm job array's `SLURM_ARRAY_TASK_ID` and `SLURM_ARRAY_TASK_COUNT`
    /// (the id made 0-based and contiguous with `SLURM_ARRAY_TASK_MIN` and
    /// `SLURM_ARRAY_TASK_STEP`), or a Kubernetes Indexed Job's `JOB_COMPLETION_INDEX` with the
    /// count in `TRANSCODE_SHARD_COUNT`. `None` when neither is set.
    pub fn from_env(var: impl Fn(&str) -> Option<String>) -> Result<Option<Self>, SequenceError> {
        let number = |name: &str| -> Result<Option<usize>, SequenceError> {
            var(name)
                .map(|v| {
                    v.trim().parse::<usize>().map_err(|_| {
                        SequenceError::Shard(format!("{name}={v} is not a whole number"))
                    })
                })
                .transpose()
        };
        if let Some(id) = number("SLURM_ARRAY_TASK_ID")? {
            let count = number("SLURM_ARRAY_TASK_COUNT")?.ok_or_else(|| {
                SequenceError::Shard(
                    "SLURM_ARRAY_TASK_ID is set but SLURM_ARRAY_TASK_COUNT is not".into(),
                )
            })?;
            let min = number("SLURM_ARRAY_TASK_MIN")?.unwrap_or(0);
            let step = number("SLURM_ARRAY_TASK_STEP")?.unwrap_or(1).max(1);
            let offset = id.checked_sub(min).ok_or_else(|| {
                SequenceError::Shard(format!(
                    "SLURM_ARRAY_TASK_ID={id} is below SLURM_ARRAY_TASK_MIN={min}"
                ))
            })?;
            if offset % step != 0 {
                return Err(SequenceError::Shard(format!(
                    "SLURM_ARRAY_TASK_ID={id} is not on the array's step {step} from {min}"
                )));
            }
            return Self::new(offset / step, count).map(Some);
        }
        if let Some(index) = number("JOB_COMPLETION_INDEX")? {
            let count = number("TRANSCODE_SHARD_COUNT")?.ok_or_else(|| {
                SequenceError::Shard(
                    "JOB_COMPLETION_INDEX is set but TRANSCODE_SHARD_COUNT (the Job's \
                     completions) is not"
                        .into(),
                )
            })?;
            return Self::new(index, count).map(Some);
        }
        if let Some(count) = var("TRANSCODE_SHARD_COUNT") {
            // A Job that is not Indexed gives no index: every pod would take every frame, all
            // at once, into one folder.
            return Err(SequenceError::Shard(format!(
                "TRANSCODE_SHARD_COUNT={count} is set but JOB_COMPLETION_INDEX is not: run the \
                 shards as an Indexed Job (completionMode: Indexed), or pass --shard I/N"
            )));
        }
        Ok(None)
    }

    /// The frames of this shard among `frames`: contiguous, sizes differing by at most one
    /// (empty when there are more shards than frames).
    #[must_use]
    pub fn block(&self, frames: usize) -> Range<usize> {
        // In u128: `index · frames` wraps usize for counts near its range (a garbage array
        // size), which gave a shard a wrong block or an inverted one.
        let at = |i: usize| (i as u128 * frames as u128 / self.count as u128) as usize;
        at(self.index)..at(self.index + 1)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn blocks_cover_every_frame_once_in_order() {
        for frames in 0..40 {
            for count in 1..12 {
                let blocks: Vec<Range<usize>> = (0..count)
                    .map(|i| Shard::new(i, count).unwrap().block(frames))
                    .collect();
                let flat: Vec<usize> = blocks.iter().cloned().flatten().collect();
                assert_eq!(flat, (0..frames).collect::<Vec<_>>());
                let sizes: Vec<usize> = blocks.iter().map(ExactSizeIterator::len).collect();
                let (lo, hi) = (sizes.iter().min().unwrap(), sizes.iter().max().unwrap());
                assert!(hi - lo <= 1, "{frames} frames in {count}: {sizes:?}");
            }
        }
        assert_eq!(Shard::new(1, 3).unwrap().block(6), 2..4);
        // Counts near usize's range: `index · frames` wrapped (a panic on an inverted range, or
        // a frame given to a shard whose block is empty).
        let huge = usize::MAX / 3;
        assert_eq!(Shard::new(huge - 1, huge).unwrap().block(3), 2..3);
        assert_eq!(Shard::new(huge / 2, huge).unwrap().block(3), 1..1);
        let last = Shard::new(usize::MAX - 1, usize::MAX).unwrap();
        assert_eq!(last.block(3), 2..3);
        assert_eq!(Shard::new(0, usize::MAX).unwrap().block(3), 0..0);
    }

    #[test]
    fn parse_and_refuse() {
        assert_eq!(Shard::parse("2/5").unwrap(), Shard { index: 2, count: 5 });
        for bad in ["5/5", "1/0", "x/2", "3", "-1/2", "1/2/3"] {
            assert!(Shard::parse(bad).is_err(), "{bad}");
        }
    }

    fn env<'a>(vars: &'a [(&'a str, &'a str)]) -> impl Fn(&str) -> Option<String> + 'a {
        move |name| {
            vars.iter()
                .find(|(k, _)| *k == name)
                .map(|(_, v)| (*v).to_string())
        }
    }

    #[test]
    fn slurm_and_kubernetes_environments() {
        assert_eq!(Shard::from_env(env(&[])).unwrap(), None);
        let slurm = [
            ("SLURM_ARRAY_TASK_ID", "7"),
            ("SLURM_ARRAY_TASK_COUNT", "4"),
            ("SLURM_ARRAY_TASK_MIN", "1"),
            ("SLURM_ARRAY_TASK_STEP", "2"),
        ];
        // --array=1-7:2 has ids 1, 3, 5, 7: id 7 is the fourth task.
        assert_eq!(
            Shard::from_env(env(&slurm)).unwrap(),
            Some(Shard { index: 3, count: 4 })
        );
        let plain = [
            ("SLURM_ARRAY_TASK_ID", "0"),
            ("SLURM_ARRAY_TASK_COUNT", "3"),
        ];
        assert_eq!(
            Shard::from_env(env(&plain)).unwrap(),
            Some(Shard { index: 0, count: 3 })
        );
        let k8s = [
            ("JOB_COMPLETION_INDEX", "2"),
            ("TRANSCODE_SHARD_COUNT", "3"),
        ];
        assert_eq!(
            Shard::from_env(env(&k8s)).unwrap(),
            Some(Shard { index: 2, count: 3 })
        );
        for bad in [
            &[("SLURM_ARRAY_TASK_ID", "1")][..],
            &[
                ("SLURM_ARRAY_TASK_ID", "one"),
                ("SLURM_ARRAY_TASK_COUNT", "2"),
            ],
            &[("JOB_COMPLETION_INDEX", "0")],
            &[
                ("JOB_COMPLETION_INDEX", "3"),
                ("TRANSCODE_SHARD_COUNT", "3"),
            ],
            // A Job that is not Indexed: it ran every pod as shard 0/1, all at once.
            &[("TRANSCODE_SHARD_COUNT", "4")],
        ] {
            assert!(Shard::from_env(env(bad)).is_err(), "{bad:?}");
        }
    }
}
