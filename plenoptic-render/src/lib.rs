//! Reference renderer: plenoptic clouds and meshes to RGB, alpha and depth images per camera,
//! the virtual camera rig that frames them, and the COLMAP dataset written from the views.
//!
//! It draws what MPEG's PccAppRenderer draws by default (`docs/reference/formats.md` §2):
//! every point an axis-aligned cube one voxel wide (or a view-aligned disc), z-buffered, coloured
//! towards the viewer with [`plenoptic_io::view_color::interpolate`] (weights max(0, cos)^n over
//! the capture cameras); meshes are rasterised with perspective-correct attributes, bilinear
//! textures, vertex colours and per-vertex plenoptic colours (interpolated at the vertices, then
//! across the triangle, as the surface shader does).
//!
//! Rendering is two passes per view: a visibility pass writes (depth, primitive id) into an atomic
//! z-buffer in parallel over primitives, then a shading pass colours only the winning primitive of
//! each pixel. Colour is constant per point, so this equals shading every fragment, and the view
//! interpolation (the expensive part) runs once per pixel instead of once per point.
//! Cameras follow COLMAP: pixel (0, 0)'s centre is at (0.5, 0.5), x right, y down, z forward.
//!
//! - [`render_cloud`], [`render_mesh`], [`render_model`], [`render_views`], [`render_views_with`],
//!   [`render_each`]:
//!   one view or many, into a [`ViewImage`], with [`ViewOptions`]; [`ModelRenderer`] prepares a
//!   model once for views rendered one at a time.
//! - [`point_sizing`]: how large a cloud's points are drawn so its surface is closed, on its
//!   voxel grid or off any grid.
//! - [`rig`]: the bounding sphere and the Fibonacci-sphere rig of training and held-out cameras.
//! - [`dataset`]: the reference views written as a COLMAP dataset (images, masks, depth, model).
//! - [`output`]: PNG and EXR writers of one view.
//! - [`degenerate`]: inputs and view sets that cannot make a model, refused with a reason.
//!
//! ```
//! use camera_model::{Camera, Intrinsics, Pose};
//! use glam::{DVec3, Vec3};
//! use plenoptic_io::PlenopticCloud;
//! use plenoptic_render::{ViewOptions, render_cloud};
//!
//! // One grey point at the origin, seen from 5 units away.
//! let mut cloud = PlenopticCloud::default();
//! cloud.positions.push(Vec3::ZERO);
//! cloud.colors.push([0.5, 0.5, 0.5]);
//! let camera = Camera::new(
//!     Intrinsics::from_fov_y(32, 32, 20.0),
//!     Pose::look_at(DVec3::new(0.0, 0.0, 5.0), DVec3::ZERO, DVec3::Y),
//! );
//! let image = render_cloud(&cloud, &camera, &ViewOptions::default()).unwrap();
//! assert_eq!(image.alpha_at(16, 16), 1.0);
//! ```

mod camera;
mod closing;
mod cloud;
mod cpu;
pub mod dataset;
pub mod degenerate;
mod error;
mod image;
mod mesh;
mod options;
pub mod output;
mod pixels;
mod render;
pub mod rig;
mod shading;
mod zbuffer;

pub use closing::{
    PointSizing, closing_point_size, grid_pitch, lies_on_grid, point_sizing, surface_spacing,
};
pub use cloud::render_cloud;
pub use dataset::{DatasetOptions, dataset_image_name, remove_dataset_model, write_dataset};
pub use degenerate::DegenerateError;
pub use error::Error;
pub use image::ViewImage;
pub use mesh::{check_mesh, render_mesh};
pub use options::{
    DEFAULT_SUPERSAMPLE, PIXEL_FILTER_VARIANCE, PixelFilter, PointShape, ViewOptions,
};
pub use output::{
    BitDepth, ViewFiles, write_alpha_png, write_depth_exr, write_rgb_png, write_view_images,
};
pub use render::{ModelRenderer, render_each, render_model, render_views, render_views_with};
pub use rig::{
    FramingSphere, MAX_CAMERAS, Rig, RigConfig, bounding_sphere, build_rig, fibonacci_rig,
};
