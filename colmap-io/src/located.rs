//! Records as a reader returns them, with where each started in its file, so that errors
//! found when the files are joined (a track naming a missing image) can point at the line or
//! byte offset.

use std::collections::{BTreeMap, HashMap};

use crate::error::{Location, Problem};
use crate::{ImageRecord, Point3D};

/// Images as read, with where each record and its POINTS2D list started (for error messages).
#[derive(Debug, Default)]
pub(crate) struct ImagesRead {
    pub images: BTreeMap<u32, ImageRecord>,
    pub record_location: BTreeMap<u32, Location>,
    pub points2d_location: BTreeMap<u32, Location>,
    /// Each file name and the image that has it.
    names: HashMap<String, u32>,
}

impl ImagesRead {
    /// Adds `image`, read at `record` with its POINTS2D list at `points2d`; refuses an id or a
    /// file name that an earlier image has (COLMAP keys images by both: two poses of one file
    /// would train one picture from two places).
    pub(crate) fn add(
        &mut self,
        image: ImageRecord,
        record: Location,
        points2d: Location,
    ) -> Result<(), Problem> {
        let id = image.id;
        if self.images.contains_key(&id) {
            return Err(Problem::DuplicateId {
                what: "image",
                id: id.into(),
            });
        }
        if let Some(&first) = self.names.get(&image.name) {
            return Err(Problem::DuplicateName {
                id,
                first,
                name: image.name,
            });
        }
        self.names.insert(image.name.clone(), id);
        self.images.insert(id, image);
        self.record_location.insert(id, record);
        self.points2d_location.insert(id, points2d);
        Ok(())
    }
}

/// Points as read, with where each record started.
#[derive(Debug, Default)]
pub(crate) struct PointsRead {
    pub points: BTreeMap<u64, Point3D>,
    pub location: BTreeMap<u64, Location>,
}
