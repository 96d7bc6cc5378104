//! Stage 2: the reference views, rendered once, as the trainer and the evaluator take them
//! (and written as the COLMAP dataset).

use std::path::Path;
use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};

use camera_model::Camera;
use plenoptic_io::Model;
use plenoptic_render::{self as views, Rig, ViewImage};
use splat_train::View;

use super::error::PipelineError;
use super::layout::Layout;
use super::{STAGES, StageClock};
use crate::config::Config;
use crate::progress::{Event, Observer};
use crate::resume::RunState;

/// Reference view `index` as the trainer wants it: straight (un-premultiplied) colour and its
/// mask ([`View::from_premultiplied`]). It takes the rendered image, so that a frame's views are
/// converted one at a time instead of held twice.
///
/// # Errors
/// [`PipelineError::Train`] naming the view and the first value that is not finite (the
/// renderer makes none; the trainer would refuse one).
pub fn training_view(
    index: usize,
    name: String,
    camera: Camera,
    image: ViewImage,
) -> Result<View, PipelineError> {
    View::from_premultiplied(name.clone(), camera, &image.rgb, &image.alpha)
        .map_err(|problem| splat_train::Error::View {
            index,
            name,
            problem,
        })
        .map_err(PipelineError::from)
}

/// The reference views as the trainer and the evaluator take them.
#[derive(Debug)]
pub struct References {
    /// Training views (straight colour with their masks), named as in the dataset; shared with
    /// the trainer, which reads them in place.
    pub train: Arc<Vec<View>>,
    /// Held-out views, for evaluation only.
    pub heldout: Vec<View>,
}

/// Stage 2: renders the training views (writing them as the COLMAP dataset unless a resumed run
/// already has) and the held-out views, and refuses a rig that sees nothing.
#[allow(clippy::too_many_arguments)]
pub(super) fn reference_views(
    input: &Path,
    model: &Model,
    rig: &Rig,
    cfg: &Config,
    layout: &Layout,
    state: &mut RunState,
    observer: Observer<'_>,
    clock: &mut StageClock,
) -> Result<References, PipelineError> {
    observer(Event::Stage {
        index: 2,
        of: STAGES,
        what: stage_description(rig, cfg),
    });
    let opts = reference_options(model, cfg, observer);
    let written_before = state.dataset_written;
    let train = if state.dataset_written || !cfg.output.dataset {
        // The dataset's PNGs are quantised: training needs the renders themselves, which are
        // deterministic, so they are made again in memory.
        if state.dataset_written {
            observer(Event::Note(
                "the dataset is already written: rendering the training views in memory".into(),
            ));
        }
        let train = collect_views(views::render_views_with(
            model,
            &rig.train,
            &opts,
            |i, image| training_view(i, views::dataset_image_name(i), rig.train[i], image),
        )?)?;
        clock.lap("render training views");
        train
    } else {
        let train = write_training_dataset(model, rig, &opts, cfg, layout, observer)?;
        state.dataset_written = true;
        state.save(&layout.out)?;
        clock.lap("render training views + write dataset");
        train
    };
    let heldout = collect_views(views::render_views_with(
        model,
        &rig.heldout,
        &opts,
        |i, image| training_view(i, heldout_name(i), rig.heldout[i], image),
    )?)?;
    let covered: Vec<bool> = heldout
        .iter()
        .map(|v| v.mask.as_ref().is_none_or(|m| m.iter().any(|&a| a > 0)))
        .collect();
    plenoptic_render::degenerate::check_coverage(input, "held-out", &covered, heldout_name)?;
    clock.lap("render held-out views");
    // A resumed run's dataset was written before (said above): not "written" again.
    if cfg.output.dataset && !written_before {
        observer(Event::Note(format!(
            "dataset written to {}",
            layout.dataset_dir.display()
        )));
    }
    Ok(References {
        train: Arc::new(train),
        heldout,
    })
}

/// What the stage's progress line says it renders.
fn stage_description(rig: &Rig, cfg: &Config) -> String {
    format!(
        "rendering {} training views{} and {} held-out views at {}×{}",
        rig.train.len(),
        if cfg.output.dataset {
            " (and the COLMAP dataset)"
        } else {
            ""
        },
        rig.heldout.len(),
        cfg.rig.width,
        cfg.rig.height
    )
}

/// The renderer's settings for the references: over black, without depth (the trainer keeps
/// colour and coverage; the dataset writer asks for depth if it writes it), with the point
/// size the cloud's sampling needs, which the observer is told of when it is not the
/// configured one.
fn reference_options(model: &Model, cfg: &Config, observer: Observer<'_>) -> views::ViewOptions {
    let sizing = cfg.renderer.point_sizing(model);
    let mut opts = cfg.renderer.sized(sizing);
    opts.background = [0.0; 3];
    opts.depth = false;
    if sizing != views::PointSizing::AsConfigured {
        observer(Event::Note(format!(
            "{sizing} (renderer.point_size = {} and renderer.close_surface = false draw them \
             at {0})",
            cfg.renderer.point_size
        )));
    }
    opts
}

/// Renders the training views and writes them as the COLMAP dataset, with a progress bar;
/// each view becomes the trainer's as soon as it is rendered (its depth dropped), so a frame's
/// full images are never all held at once.
fn write_training_dataset(
    model: &Model,
    rig: &Rig,
    opts: &views::ViewOptions,
    cfg: &Config,
    layout: &Layout,
    observer: Observer<'_>,
) -> Result<Vec<View>, PipelineError> {
    let dataset_opts = views::DatasetOptions {
        bit_depth: if cfg.output.png16 {
            views::BitDepth::Sixteen
        } else {
            views::BitDepth::Eight
        },
        masks: true,
        depth: false,
    };
    observer(Event::Begin {
        unit: "views",
        total: rig.train.len() as u64,
        done: 0,
    });
    let done = AtomicU64::new(0);
    let train = collect_views(views::write_dataset(
        &layout.dataset_dir,
        model,
        &rig.train,
        opts,
        &dataset_opts,
        &|| {
            let n = done.fetch_add(1, Ordering::Relaxed) + 1;
            observer(Event::Advance {
                done: n,
                message: None,
            });
        },
        |i, image| training_view(i, views::dataset_image_name(i), rig.train[i], image),
    )?)?;
    observer(Event::End);
    Ok(train)
}

/// The views, or the first view's error.
fn collect_views(views: Vec<Result<View, PipelineError>>) -> Result<Vec<View>, PipelineError> {
    views.into_iter().collect()
}

/// The name of held-out view `i` in reports and messages.
fn heldout_name(i: usize) -> String {
    format!("heldout_{i:03}")
}
