//! Records as a reader returns them, with where each started in its file, so that errors
//! found when the files are joined (a track naming a missing image) can point at the line or
//! byte offset.

use std::collections::BTreeMap;

use crate::error::Location;
use crate::{ImageRecord, Point3D};

/// Images as read, with where each record and its POINTS2D list started (for error messages).
#[derive(Debug, Default)]
pub(crate) struct ImagesRead {
    pub images: BTreeMap<u32, ImageRecord>,
    pub record_location: BTreeMap<u32, Location>,
    pub points2d_location: BTreeMap<u32, Location>,
}

/// Points as read, with where each record started.
#[derive(Debug, Default)]
pub(crate) struct PointsRead {
    pub points: BTreeMap<u64, Point3D>,
    pub location: BTreeMap<u64, Location>,
}
