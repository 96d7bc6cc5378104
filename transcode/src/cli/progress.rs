//! The pipeline's progress on stderr: stage lines, notes and a progress bar per counted task.

use std::sync::Mutex;

use indicatif::{ProgressBar, ProgressStyle};
use transcode::progress::Event;

/// Draws [`Event`]s on stderr (nothing when quiet).
pub struct Reporter {
    quiet: bool,
    bar: Mutex<Option<ProgressBar>>,
}

impl Reporter {
    /// A reporter that draws, or with `quiet` stays silent.
    pub fn new(quiet: bool) -> Self {
        Self {
            quiet,
            bar: Mutex::new(None),
        }
    }

    /// Shows one event.
    pub fn show(&self, event: Event) {
        if self.quiet {
            return;
        }
        // A poisoned lock only means another thread panicked while drawing: keep drawing.
        let mut bar = self.bar.lock().unwrap_or_else(|e| e.into_inner());
        match event {
            Event::Stage { index, of, what } => eprintln!("[{index}/{of}] {what}"),
            Event::Note(note) => eprintln!("      {note}"),
            Event::Frame {
                index,
                of,
                name,
                what,
            } => eprintln!("== frame {index}/{of}: {name} ({what})"),
            Event::Begin { unit, total, done } => {
                let b = ProgressBar::new(total);
                b.set_style(
                    ProgressStyle::with_template(&format!(
                        "      {{bar:30}} {{pos}}/{{len}} {unit}, {{elapsed_precise}} elapsed, ETA {{eta}} {{msg}}"
                    ))
                    .unwrap_or_else(|_| ProgressStyle::default_bar()),
                );
                b.set_position(done);
                *bar = Some(b);
            }
            Event::Total(total) => {
                if let Some(b) = bar.as_ref() {
                    b.set_length(total);
                }
            }
            Event::Advance { done, message } => {
                if let Some(b) = bar.as_ref() {
                    b.set_position(done);
                    if let Some(m) = message {
                        b.set_message(m);
                    }
                }
            }
            Event::End => {
                if let Some(b) = bar.take() {
                    b.finish_and_clear();
                }
            }
        }
    }
}
