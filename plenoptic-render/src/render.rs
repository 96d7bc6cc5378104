//! Rendering a model (cloud or mesh) from one camera or a set of cameras.

use camera_model::Camera;
use plenoptic_io::Model;
use rayon::prelude::*;

use crate::{Error, ViewImage, ViewOptions, render_cloud, render_mesh};

/// Renders a cloud or a mesh (see [`render_cloud`] and [`render_mesh`]).
pub fn render_model(
    model: &Model,
    camera: &Camera,
    opts: &ViewOptions,
) -> Result<ViewImage, Error> {
    match model {
        Model::Cloud(cloud) => render_cloud(cloud, camera, opts),
        Model::Mesh(mesh) => render_mesh(mesh, camera, opts),
    }
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
    let opts = &opts.for_model(model);
    cameras
        .par_iter()
        .enumerate()
        .try_for_each(|(i, camera)| sink(i, render_model(model, camera, opts)?))
}

/// Renders `model` from every camera, in parallel over views, and returns the images in order.
pub fn render_views(
    model: &Model,
    cameras: &[Camera],
    opts: &ViewOptions,
) -> Result<Vec<ViewImage>, Error> {
    let opts = &opts.for_model(model);
    cameras
        .par_iter()
        .map(|camera| render_model(model, camera, opts))
        .collect()
}
