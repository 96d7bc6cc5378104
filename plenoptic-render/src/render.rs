//! Rendering a model (cloud or mesh) from one camera or a set of cameras.

use camera_model::Camera;
use plenoptic_io::{Mesh, Model};
use rayon::prelude::*;

use crate::cloud::PreparedCloud;
use crate::mesh::{check_mesh, render_checked_mesh};
use crate::{Error, ViewImage, ViewOptions};

/// A model made ready to be drawn from any number of cameras: checked, a cloud's point size
/// chosen and its points ordered for drawing, once rather than once a view. [`render_each`]
/// and [`render_views`] use one; make one yourself to render views one at a time.
pub struct ModelRenderer<'a> {
    prepared: Prepared<'a>,
}

enum Prepared<'a> {
    Cloud(PreparedCloud<'a>),
    Mesh(&'a Mesh, ViewOptions),
}

impl<'a> ModelRenderer<'a> {
    /// Checks `model` and `opts` and prepares the model for drawing.
    pub fn new(model: &'a Model, opts: &ViewOptions) -> Result<Self, Error> {
        let prepared = match model {
            Model::Cloud(cloud) => Prepared::Cloud(PreparedCloud::new(cloud, opts)?),
            Model::Mesh(mesh) => {
                opts.validate()?;
                check_mesh(mesh)?;
                Prepared::Mesh(mesh, opts.clone())
            }
        };
        Ok(Self { prepared })
    }

    /// Says that `n` more views are to be rendered, so that no buffers are kept for views that
    /// will not come (the functions rendering a set of cameras say it; views rendered one at a
    /// time keep a set a thread until the renderer is dropped).
    pub(crate) fn expect_views(&self, n: usize) {
        if let Prepared::Cloud(cloud) = &self.prepared {
            cloud.expect_views(n);
        }
    }

    /// The model seen from `camera`.
    pub fn render(&self, camera: &Camera) -> Result<ViewImage, Error> {
        match &self.prepared {
            Prepared::Cloud(cloud) => cloud.render(camera),
            Prepared::Mesh(mesh, opts) => render_checked_mesh(mesh, camera, opts),
        }
    }
}

/// Renders a cloud or a mesh (see [`crate::render_cloud`] and [`crate::render_mesh`]).
pub fn render_model(
    model: &Model,
    camera: &Camera,
    opts: &ViewOptions,
) -> Result<ViewImage, Error> {
    ModelRenderer::new(model, opts)?.render(camera)
}

/// Renders `model` from every camera, in parallel over views, handing each finished view to
/// `sink` (view index, image) as soon as it is done, so that callers can write and drop it.
pub fn render_each<F>(
    model: &Model,
    cameras: &[Camera],
    opts: &ViewOptions,
    sink: F,
) -> Result<(), Error>
where
    F: Fn(usize, ViewImage) -> Result<(), Error> + Sync + Send,
{
    let renderer = ModelRenderer::new(model, opts)?;
    renderer.expect_views(cameras.len());
    cameras
        .par_iter()
        .enumerate()
        .try_for_each(|(i, camera)| sink(i, renderer.render(camera)?))
}

/// Renders `model` from every camera, in parallel over views, and returns the images in order.
pub fn render_views(
    model: &Model,
    cameras: &[Camera],
    opts: &ViewOptions,
) -> Result<Vec<ViewImage>, Error> {
    render_views_with(model, cameras, opts, |_, image| image)
}

/// Renders `model` from every camera, in parallel over views, and returns `keep(i, image)` of
/// each view i in camera order. `keep` runs as soon as a view is finished, so a caller that keeps
/// less than the whole image (a trainer's view without depth, a flag) never holds all of a
/// frame's full images at once: 44 views at 1024² are 0.9 GB.
pub fn render_views_with<T, F>(
    model: &Model,
    cameras: &[Camera],
    opts: &ViewOptions,
    keep: F,
) -> Result<Vec<T>, Error>
where
    T: Send,
    F: Fn(usize, ViewImage) -> T + Sync + Send,
{
    let renderer = ModelRenderer::new(model, opts)?;
    renderer.expect_views(cameras.len());
    cameras
        .par_iter()
        .enumerate()
        .map(|(i, camera)| Ok(keep(i, renderer.render(camera)?)))
        .collect()
}
