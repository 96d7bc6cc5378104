//! A WebGL2 viewer for 3D Gaussian splats, and a small local server for it.
//!
//! The viewer is static files (HTML, JavaScript, GLSL) written in this crate and embedded in it:
//! no framework, nothing loaded from the network, so a page works from a copied folder and
//! offline. It renders with the projection, SH evaluation and compositing constants of
//! `splat-core` (a test here pins the shader's constants to that crate's), sorts splats back to
//! front in a web worker as the camera moves, and at a held-out camera compares the live render
//! with the reference, the CPU render and the error map.
//!
//! - [`Scene`], [`SceneView`], [`ViewCamera`]: what the viewer shows (a model, cameras, pictures).
//! - [`write_folder`]: writes the viewer and a scene into a folder beside a report;
//!   [`report_section`]: the HTML that embeds it in a page.
//! - [`assets`]: the viewer's files as the server hands them out.
//! - [`Site`], [`Server`]: a static file server that never serves outside its folder.
//! - [`Error`]: I/O, binding and JSON errors.

pub mod assets;
mod error;
mod folder;
mod scene;
mod server;
mod site;

pub use error::Error;
pub use folder::{EMBED_LIMIT, model_site, report_section, write_folder};
pub use scene::{Scene, SceneModel, SceneView, ViewCamera, ViewImages};
pub use server::{
    CONNECTION_LIFETIME, FILE_CHUNK, HEADER_TIMEOUT, MAX_CONNECTIONS, MAX_REQUEST_HEAD, Server,
};
pub use site::{Content, Found, Refusal, Site, content_type};
