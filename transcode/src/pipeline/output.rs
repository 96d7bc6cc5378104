//! Stages 5 and 6: each model's evaluation, its files in the formats asked for, and the report.

use std::path::{Path, PathBuf};
use std::time::Instant;

use splat_core::Splats;
use splat_train::View;
use splat_train::eval::{Metrics, RenderedView, evaluate_views};

use super::error::{PipelineError, io_err};
use super::input::Surfaces;
use super::layout::Layout;
use super::references::References;
use super::{Outcome, STAGES, StageClock, TrainedModel};
use crate::config::{Config, InitMode};
use crate::progress::{Event, Observer};
use crate::report::{InputInfo, Report, StageTiming, ViewPictures, write_report};

/// Stage 5: scores a trained model on the held-out views.
pub(super) fn evaluate(
    mode: InitMode,
    splats: &Splats,
    refs: &References,
    surfaces: &Surfaces,
    cfg: &Config,
    observer: Observer<'_>,
) -> Result<(Metrics, Vec<RenderedView>), PipelineError> {
    observer(Event::Stage {
        index: 5,
        of: STAGES,
        what: format!("evaluating the {mode} model"),
    });
    Ok(evaluate_views(
        splats,
        &refs.heldout,
        surfaces.distance.as_ref(),
        &cfg.eval_options(),
    )?)
}

/// Stage 5 (end): writes every model in the formats asked for, noting sizes in its report.
pub(super) fn export(
    trained: &mut [TrainedModel],
    cfg: &Config,
    observer: Observer<'_>,
) -> Result<(), PipelineError> {
    if cfg.training.antialiased {
        observer(Event::Note(
            "the model was trained antialiased (training.antialiased): its PLY says so in a \
             header comment (SplatRenderMode: mip) and its SPZ in a flag, which our viewer, \
             Brush, PlayCanvas / SuperSplat and splat-transform read; a viewer that ignores them \
             draws it with more coverage than it was trained to have, and .splat and .glb files \
             cannot say it (docs/benchmarks/fidelity.md sections 14 and 15)"
                .into(),
        ));
    }
    for (k, model) in trained.iter_mut().enumerate() {
        let run = &mut model.report;
        observer(Event::Stage {
            index: 5,
            of: STAGES,
            what: format!("writing {}", run.model_path.display()),
        });
        let t = Instant::now();
        let formats = ModelFormats {
            antialiased: cfg.training.antialiased,
            splat: k == 0 && cfg.output.splat_file,
            spz: cfg.output.spz.then_some(cfg.output.spz_version),
            glb: cfg.output.glb,
        };
        let compact = write_model(&run.model_path, &model.splats, formats)?;
        run.model_bytes = std::fs::metadata(&run.model_path).map_or(0, |m| m.len());
        run.compact_files = compact
            .into_iter()
            .map(|p| {
                let bytes = std::fs::metadata(&p).map_or(0, |m| m.len());
                (p, bytes)
            })
            .collect();
        run.timings.push(StageTiming {
            stage: "write model".to_string(),
            seconds: t.elapsed().as_secs_f64(),
        });
    }
    Ok(())
}

/// Stage 6: writes the report (JSON and HTML).
#[allow(clippy::too_many_arguments)]
pub(super) fn report(
    input: &InputInfo,
    refs: &References,
    trained: Vec<TrainedModel>,
    cfg: &Config,
    layout: &Layout,
    mut clock: StageClock,
    started: Instant,
    resumed: bool,
    observer: Observer<'_>,
) -> Result<Outcome, PipelineError> {
    observer(Event::Stage {
        index: 6,
        of: STAGES,
        what: "writing the report".to_string(),
    });
    let renders: Vec<Vec<RenderedView>> = trained.iter().map(|t| t.renders.clone()).collect();
    let pictures = pick_pictures(&refs.heldout, &renders, cfg.eval.report_views);
    if let Some(main) = trained.first() {
        let title = format!("transcode: {}", input.path.display());
        crate::viewer::write_report_viewer(
            &layout.report_dir,
            &title,
            &main.splats,
            cfg.training.antialiased,
            &refs.heldout,
            &main.renders,
        )?;
    }
    clock.lap("report viewer");
    let mut report = Report {
        version: env!("CARGO_PKG_VERSION").to_string(),
        input: input.clone(),
        config: cfg.clone(),
        train_views: refs.train.len(),
        heldout_views: refs.heldout.len(),
        timings: clock.timings,
        runs: trained.into_iter().map(|t| t.report).collect(),
        total_seconds: 0.0,
        resumed,
    };
    report.total_seconds = started.elapsed().as_secs_f64();
    let html =
        write_report(&layout.report_dir, &report, &pictures).map_err(io_err(&layout.report_dir))?;
    Ok(Outcome {
        report,
        html,
        model: layout.main_model(),
    })
}

/// The files written beside a model's PLY.
#[derive(Clone, Copy, Debug)]
struct ModelFormats {
    /// The model was trained antialiased (the PLY's header and the SPZ's flag say so).
    antialiased: bool,
    splat: bool,
    /// The SPZ version to write, if any.
    spz: Option<u32>,
    glb: bool,
}

/// Writes the model PLY and the other formats asked for, each atomically, beside it; returns the
/// paths of the others.
fn write_model(
    path: &Path,
    splats: &Splats,
    formats: ModelFormats,
) -> Result<Vec<PathBuf>, PipelineError> {
    let model_err = |p: &Path| {
        let p = p.to_path_buf();
        move |source: splat_core::Error| PipelineError::Model {
            path: p,
            source: Box::new(source),
        }
    };
    // Each file by its extension, the render mode marked where the format has a place for it.
    let spz = splat_core::spz::SpzOptions {
        version: formats.spz.unwrap_or(splat_core::spz::VERSION),
        ..splat_core::spz::SpzOptions::default()
    };
    let write = |p: &Path| {
        splat_core::model_file::write_model(p, splats, formats.antialiased, &spz)
            .map_err(model_err(p))
    };
    write(path)?;
    let mut written = Vec::new();
    for (ext, wanted) in [
        ("splat", formats.splat),
        ("spz", formats.spz.is_some()),
        ("glb", formats.glb),
    ] {
        if wanted {
            let p = path.with_extension(ext);
            write(&p)?;
            written.push(p);
        }
    }
    Ok(written)
}

/// Pictures of up to `n` held-out views spread over the set.
fn pick_pictures(heldout: &[View], renders: &[Vec<RenderedView>], n: usize) -> Vec<ViewPictures> {
    let n = n.min(heldout.len());
    (0..n)
        .map(|k| k * heldout.len() / n.max(1))
        .map(|i| {
            let v = &heldout[i];
            ViewPictures {
                name: v.name.clone(),
                width: v.camera.intrinsics.width,
                height: v.camera.intrinsics.height,
                reference: v
                    .on_background([0.0; 3])
                    .iter()
                    .map(|x| x.clamp(0.0, 1.0))
                    .collect(),
                renders: renders.iter().map(|r| r[i].rgb.clone()).collect(),
            }
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_model_file_that_can_say_the_model_was_trained_antialiased_says_so() {
        let splats = Splats::from_points(
            &[glam::Vec3::ZERO, glam::Vec3::X],
            &[[1.0, 0.5, 0.0], [0.0, 0.5, 1.0]],
            &[glam::Vec3::splat(0.1); 2],
            None,
            0.9,
            1,
        )
        .unwrap();
        let dir = tempfile::tempdir().unwrap();
        for antialiased in [false, true] {
            let path = dir.path().join(format!("splats{antialiased}.ply"));
            let formats = ModelFormats {
                antialiased,
                splat: true,
                spz: Some(if antialiased { 4 } else { 3 }),
                glb: true,
            };
            let others = write_model(&path, &splats, formats).unwrap();
            assert_eq!(others.len(), 3);
            for p in std::iter::once(path).chain(others) {
                let file = splat_core::model_file::read_model(&p).unwrap();
                assert_eq!(file.splats.len(), 2);
                let recorded = antialiased && file.format.records_antialiased();
                assert_eq!(file.antialiased, recorded, "{}", p.display());
            }
        }
    }
}
