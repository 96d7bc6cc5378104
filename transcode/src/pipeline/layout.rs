//! The run's output folder: its folders and files, what marks a run finished, and the saved
//! state a killed run continues from.

use std::path::{Path, PathBuf};

use super::error::{PipelineError, io_err};
use crate::config::{Config, InitMode};
use crate::progress::{Event, Observer};
use crate::report::VIEWER_DIR;
use crate::resume::{self, InputStamp, ResumeError, RunState, Status};

/// Every extension a model file of a run may have: a run deletes them all before it starts.
const MODEL_EXTENSIONS: [&str; 4] = ["ply", "splat", "spz", "glb"];

/// The folders and files of a run in its output folder.
#[derive(Debug, Clone)]
pub(super) struct Layout {
    pub(super) out: PathBuf,
    model_dir: PathBuf,
    pub(super) report_dir: PathBuf,
    pub(super) dataset_dir: PathBuf,
    pub(super) checkpoints: PathBuf,
}

impl Layout {
    pub(super) fn new(out: &Path) -> Self {
        Self {
            out: out.to_path_buf(),
            model_dir: out.join("model"),
            report_dir: out.join("report"),
            dataset_dir: out.join("dataset"),
            checkpoints: out.join(resume::CHECKPOINT_DIR),
        }
    }

    /// `model/splats.ply`: the first init mode's model.
    pub(super) fn main_model(&self) -> PathBuf {
        self.model_dir.join("splats.ply")
    }

    /// `report/report.html`.
    pub(super) fn html(&self) -> PathBuf {
        self.report_dir.join("report.html")
    }

    /// The model of the `k`-th init mode: `splats.ply`, then `splats-MODE.ply`.
    pub(super) fn model_path(&self, k: usize, mode: InitMode) -> PathBuf {
        if k == 0 {
            self.main_model()
        } else {
            self.model_dir.join(format!("splats-{mode}.ply"))
        }
    }

    /// Removes what marks a finished run, and for a fresh run the saved state and checkpoints.
    ///
    /// Markers of a finished run go first, so a failure later cannot leave an old,
    /// complete-looking model or report beside new, partial data; a fresh run must not pick up an
    /// earlier run's state or checkpoints.
    pub(super) fn clear_results(&self, fresh: bool) -> Result<(), PipelineError> {
        let models = ["splats", "splats-sparse", "splats-surface"]
            .into_iter()
            .flat_map(|stem| {
                MODEL_EXTENSIONS.map(|ext| self.model_dir.join(format!("{stem}.{ext}")))
            });
        let reports = [self.report_dir.join("report.json"), self.html()];
        for marker in models.chain(reports) {
            remove_file_if_present(&marker)?;
        }
        // The report's viewer holds a copy of the old model: `transcode view` would serve it.
        remove_dir_if_present(&self.report_dir.join(VIEWER_DIR))?;
        if fresh {
            remove_file_if_present(&self.out.join(resume::STATE_FILE))?;
            remove_dir_if_present(&self.checkpoints)?;
            // An earlier input's dataset is not this run's (a resumed run keeps its own).
            plenoptic_render::remove_dataset_model(&self.dataset_dir)
                .map_err(|e| PipelineError::Views(Box::new(e)))?;
        }
        Ok(())
    }

    /// Refuses an input that lies in one of the folders a run clears (`model/`, `report/`,
    /// `dataset/`, the checkpoints) or is its saved state: the run would delete or overwrite
    /// it before reading it. An input that cannot be resolved is left to the loader to report.
    pub(super) fn check_input_outside(&self, input: &Path) -> Result<(), PipelineError> {
        let Ok(input) = input.canonicalize() else {
            return Ok(());
        };
        let cleared = [
            &self.model_dir,
            &self.report_dir,
            &self.dataset_dir,
            &self.checkpoints,
        ];
        for folder in cleared {
            if folder
                .canonicalize()
                .is_ok_and(|folder| input.starts_with(folder))
            {
                return Err(PipelineError::InputInOutput {
                    input,
                    folder: folder.clone(),
                });
            }
        }
        let state = self.out.join(resume::STATE_FILE);
        if state.canonicalize().is_ok_and(|state| state == input) {
            return Err(PipelineError::InputInOutput {
                input,
                folder: self.out.clone(),
            });
        }
        Ok(())
    }

    /// The file whose lock a run holds while it writes here ([`crate::lock`]).
    pub(super) fn lock_file(&self) -> PathBuf {
        self.out.join(".transcode.lock")
    }

    /// Creates the run's folders (`dataset/` only when it is written).
    pub(super) fn create(&self, dataset: bool) -> Result<(), PipelineError> {
        for d in [&self.model_dir, &self.report_dir, &self.checkpoints] {
            std::fs::create_dir_all(d).map_err(io_err(d))?;
        }
        if dataset {
            std::fs::create_dir_all(&self.dataset_dir).map_err(io_err(&self.dataset_dir))?;
        }
        Ok(())
    }
}

/// The saved state to continue, or a new one; from here until the end the folder says "running".
pub(super) fn open_state(
    input: &Path,
    cfg: &Config,
    layout: &Layout,
    saved: Option<RunState>,
    observer: Observer<'_>,
) -> Result<RunState, PipelineError> {
    let mut state = match saved {
        Some(s) => {
            observer(Event::Note(format!(
                "resuming the run in {} ({})",
                layout.out.display(),
                resume_summary(&s)
            )));
            s
        }
        None => {
            let stamp = InputStamp::of(input).map_err(|source| ResumeError::Io {
                path: input.to_path_buf(),
                source,
            })?;
            RunState::start(stamp, cfg)
        }
    };
    state.status = Status::Running;
    state.save(&layout.out)?;
    Ok(state)
}

/// Removes `path` (a file) unless it is not there.
pub(super) fn remove_file_if_present(path: &Path) -> Result<(), PipelineError> {
    match std::fs::remove_file(path) {
        Ok(()) => Ok(()),
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => Ok(()),
        Err(e) => Err(io_err(path)(e)),
    }
}

/// Removes the folder `path` and its contents unless it is not there.
pub(super) fn remove_dir_if_present(path: &Path) -> Result<(), PipelineError> {
    match std::fs::remove_dir_all(path) {
        Ok(()) => Ok(()),
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => Ok(()),
        Err(e) => Err(io_err(path)(e)),
    }
}

/// One line on what a saved run has done.
fn resume_summary(s: &RunState) -> String {
    let mut parts = vec![if s.dataset_written {
        "dataset written".to_string()
    } else {
        "dataset not written".to_string()
    }];
    for m in &s.modes {
        parts.push(format!(
            "{} {}",
            m.mode,
            if m.trained.is_some() {
                "trained"
            } else {
                "training"
            }
        ));
    }
    parts.join(", ")
}
