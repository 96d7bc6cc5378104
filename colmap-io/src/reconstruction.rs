//! The records of a COLMAP model and their consistency rules.

use std::collections::BTreeMap;

use camera_model::{Camera, Intrinsics, Pose};
use glam::{DVec2, DVec3};

use crate::{CameraModel, Error, Problem};

/// One row of `cameras.txt` / `cameras.bin`.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct CameraRecord {
    /// Camera id (`camera_t`).
    pub id: u32,
    /// Camera model.
    pub model: CameraModel,
    /// Image width in pixels.
    pub width: u64,
    /// Image height in pixels.
    pub height: u64,
    /// Model parameters in COLMAP order (see [`CameraModel::param_names`]).
    pub params: Vec<f64>,
}

/// The first of `values` that is NaN or infinite, as its index and a [`Problem::NonFinite`]
/// naming the record and the field.
fn first_non_finite(
    record: &'static str,
    id: u64,
    values: &[f64],
    field: impl Fn(usize) -> String,
) -> Option<(usize, Problem)> {
    let i = values.iter().position(|v| !v.is_finite())?;
    Some((
        i,
        Problem::NonFinite {
            record,
            id,
            field: field(i),
            value: values[i],
        },
    ))
}

/// Where in a camera record a problem lies, for the readers to point at its line or bytes.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum CameraField {
    /// WIDTH or HEIGHT (the first of them that is 0).
    Width,
    Height,
    /// The parameter of this index.
    Param(usize),
}

impl CameraRecord {
    /// The first field that makes the camera unusable: a width or height of 0 (no pixels), a
    /// parameter that is NaN or infinite (every projection NaN), or a focal length (`f`, `fx`,
    /// `fy`) that is not positive (every point projected onto the principal point, or
    /// mirrored).
    pub(crate) fn bad_intrinsics(&self) -> Option<(CameraField, Problem)> {
        let id = u64::from(self.id);
        if self.width == 0 || self.height == 0 {
            let field = if self.width == 0 {
                CameraField::Width
            } else {
                CameraField::Height
            };
            let (width, height) = (self.width, self.height);
            return Some((field, Problem::ZeroSize { id, width, height }));
        }
        let names = self.model.param_names();
        let name = |i: usize| format!("PARAMS[{i}] ({})", names.get(i).copied().unwrap_or("?"));
        if let Some((i, problem)) = first_non_finite("camera", id, &self.params, name) {
            return Some((CameraField::Param(i), problem));
        }
        let focal = |i: &usize| matches!(names.get(*i), Some(&("f" | "fx" | "fy")));
        let i = (0..self.params.len())
            .filter(focal)
            .find(|&i| self.params[i] <= 0.0)?;
        Some((
            CameraField::Param(i),
            Problem::NotPositive {
                id,
                field: name(i),
                value: self.params[i],
            },
        ))
    }
}

/// One 2D observation of an image: a keypoint, possibly triangulated.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Point2D {
    /// Pixel position (pixel (0, 0)'s centre at (0.5, 0.5)).
    pub xy: DVec2,
    /// The 3D point it observes; `None` is written as −1 (text) or `u64::MAX` (binary).
    pub point3d_id: Option<u64>,
}

/// One image of `images.txt` / `images.bin`.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct ImageRecord {
    /// Image id (`image_t`).
    pub id: u32,
    /// World→camera rotation quaternion `[w, x, y, z]`, exactly as stored in the file.
    pub qvec: [f64; 4],
    /// World→camera translation, exactly as stored in the file.
    pub tvec: [f64; 3],
    /// The camera (intrinsics) this image was taken with.
    pub camera_id: u32,
    /// File name relative to the images folder (no whitespace).
    pub name: String,
    /// Keypoints with their 3D point ids.
    pub points2d: Vec<Point2D>,
}

impl ImageRecord {
    /// The image's name as a path under the images folder (subfolders kept), or `None` where the
    /// name would lead out of it: absolute, with a `..` segment, or empty. Readers of a dataset
    /// and writers named after its images join only this to their folder, so a model's names
    /// cannot make them read or write elsewhere.
    #[must_use]
    pub fn relative_file(&self) -> Option<&std::path::Path> {
        use std::path::{Component, Path};
        let path = Path::new(&self.name);
        let inside = path.file_name().is_some()
            && path
                .components()
                .all(|c| matches!(c, Component::Normal(_) | Component::CurDir));
        inside.then_some(path)
    }

    /// The first pose number that is NaN or infinite (its index in QW QX QY QZ TX TY TZ), or a
    /// quaternion too close to zero to normalise (index 0): either makes every projection NaN.
    pub(crate) fn bad_pose(&self) -> Option<(usize, Problem)> {
        const FIELDS: [&str; 7] = ["QW", "QX", "QY", "QZ", "TX", "TY", "TZ"];
        let pose = [self.qvec.as_slice(), &self.tvec].concat();
        first_non_finite("image", self.id.into(), &pose, |i| FIELDS[i].to_string()).or_else(|| {
            // Files round their unit quaternions to a few digits; a norm of 10⁻⁶ is no rotation.
            let norm2: f64 = self.qvec.iter().map(|v| v * v).sum();
            (norm2 < 1e-12).then(|| {
                (
                    0,
                    Problem::ZeroRotation {
                        id: self.id.into(),
                        qvec: self.qvec,
                    },
                )
            })
        })
    }
}

/// One observation in a 3D point's track.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub struct TrackElement {
    /// The observing image.
    pub image_id: u32,
    /// Index of the observation in that image's `points2d`.
    pub point2d_idx: u32,
}

/// One 3D point of `points3D.txt` / `points3D.bin`.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Point3D {
    /// World position.
    pub xyz: DVec3,
    /// Colour, 8 bits per channel.
    pub rgb: [u8; 3],
    /// Mean reprojection error in pixels (COLMAP writes −1 when unknown).
    pub error: f64,
    /// Observations of the point.
    pub track: Vec<TrackElement>,
}

impl Point3D {
    /// The first coordinate that is NaN or infinite (its index in X Y Z), for the point `id`.
    pub(crate) fn non_finite(&self, id: u64) -> Option<(usize, Problem)> {
        first_non_finite("point3D", id, &self.xyz.to_array(), |i| {
            ["X", "Y", "Z"][i].to_string()
        })
    }
}

/// A COLMAP sparse model: cameras, registered images and 3D points, keyed by id.
#[derive(Debug, Clone, Default, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Reconstruction {
    /// Cameras by id.
    pub cameras: BTreeMap<u32, CameraRecord>,
    /// Images by id.
    pub images: BTreeMap<u32, ImageRecord>,
    /// 3D points by id.
    pub points3d: BTreeMap<u64, Point3D>,
}

impl CameraRecord {
    /// A PINHOLE record of pinhole intrinsics; refused when the intrinsics have skew, which
    /// no COLMAP model holds.
    pub fn from_intrinsics(id: u32, k: &Intrinsics) -> Result<Self, Error> {
        if k.skew != 0.0 {
            return Err(Error::Unrepresentable(format!(
                "camera {id} has skew {}, which COLMAP's PINHOLE model cannot hold",
                k.skew
            )));
        }
        Ok(Self {
            id,
            model: CameraModel::Pinhole,
            width: u64::from(k.width),
            height: u64::from(k.height),
            params: vec![k.fx, k.fy, k.cx, k.cy],
        })
    }

    /// Pinhole intrinsics of a SIMPLE_PINHOLE or PINHOLE camera; distorted models are refused
    /// with [`Error::NotPinhole`].
    pub fn intrinsics(&self) -> Result<Intrinsics, Error> {
        let (fx, fy, cx, cy) = match (self.model, self.params.as_slice()) {
            (CameraModel::SimplePinhole, &[f, cx, cy]) => (f, f, cx, cy),
            (CameraModel::Pinhole, &[fx, fy, cx, cy]) => (fx, fy, cx, cy),
            (CameraModel::SimplePinhole | CameraModel::Pinhole, p) => {
                return Err(Error::Invalid(Problem::ParamCount {
                    model: self.model.name(),
                    expected: self.model.num_params(),
                    found: p.len(),
                }));
            }
            (model, _) => {
                return Err(Error::NotPinhole {
                    camera_id: self.id,
                    model: model.name(),
                });
            }
        };
        let size = |v: u64, what: &str| {
            u32::try_from(v).map_err(|_| {
                Error::Unrepresentable(format!("camera {} {what} {v} exceeds u32", self.id))
            })
        };
        Ok(Intrinsics {
            width: size(self.width, "width")?,
            height: size(self.height, "height")?,
            fx,
            fy,
            cx,
            cy,
            skew: 0.0,
        })
    }
}

impl ImageRecord {
    /// An image record with a pose and no keypoints.
    #[must_use]
    pub fn new(id: u32, camera_id: u32, name: impl Into<String>, pose: &Pose) -> Self {
        Self {
            id,
            qvec: pose.wxyz(),
            tvec: pose.translation.to_array(),
            camera_id,
            name: name.into(),
            points2d: Vec::new(),
        }
    }

    /// The world→camera pose (quaternion normalised).
    #[must_use]
    pub fn pose(&self) -> Pose {
        Pose::from_wxyz(self.qvec, self.tvec)
    }
}

impl Reconstruction {
    /// The pinhole camera of an image (its intrinsics and pose).
    pub fn camera_of(&self, image_id: u32) -> Result<Camera, Error> {
        let image = self.images.get(&image_id).ok_or_else(|| {
            Error::Unrepresentable(format!("the reconstruction has no image {image_id}"))
        })?;
        let record =
            self.cameras
                .get(&image.camera_id)
                .ok_or(Error::Invalid(Problem::MissingCamera {
                    image_id,
                    camera_id: image.camera_id,
                }))?;
        Ok(Camera::new(record.intrinsics()?, image.pose()))
    }

    /// Total number of 2D observations that refer to a 3D point.
    #[must_use]
    pub fn num_observations(&self) -> usize {
        self.points3d.values().map(|p| p.track.len()).sum()
    }

    /// Reprojection error in pixels of every track element, through [`Camera::project`];
    /// needs pinhole cameras. Observations behind their camera give `f64::INFINITY`.
    pub fn reprojection_errors(&self) -> Result<Vec<f64>, Error> {
        let cameras: BTreeMap<u32, Camera> = self
            .images
            .keys()
            .map(|&id| self.camera_of(id).map(|c| (id, c)))
            .collect::<Result<_, _>>()?;
        let mut errors = Vec::with_capacity(self.num_observations());
        for (&pid, point) in &self.points3d {
            for t in &point.track {
                let observed = self
                    .images
                    .get(&t.image_id)
                    .and_then(|im| im.points2d.get(t.point2d_idx as usize))
                    .zip(cameras.get(&t.image_id))
                    .ok_or(Error::Invalid(Problem::MissingObservation {
                        point3d_id: pid,
                        image_id: t.image_id,
                        point2d_idx: t.point2d_idx,
                    }))?;
                let (obs, cam) = observed;
                errors.push(
                    cam.project(point.xyz)
                        .map_or(f64::INFINITY, |px| (px - obs.xy).length()),
                );
            }
        }
        Ok(errors)
    }

    /// Checks that every reference resolves: images to cameras, observations to 3D points,
    /// track elements to observations.
    pub fn validate(&self) -> Result<(), Error> {
        self.validate_images().map_err(Error::Invalid)?;
        self.validate_points().map_err(|(_, p)| Error::Invalid(p))
    }

    /// The first image whose camera or observations dangle.
    pub(crate) fn validate_images(&self) -> Result<(), Problem> {
        self.images
            .values()
            .try_for_each(|image| self.validate_image(image))
    }

    /// Checks one image's camera and 3D point references.
    pub(crate) fn validate_image(&self, image: &ImageRecord) -> Result<(), Problem> {
        if !self.cameras.contains_key(&image.camera_id) {
            return Err(Problem::MissingCamera {
                image_id: image.id,
                camera_id: image.camera_id,
            });
        }
        for (idx, p) in image.points2d.iter().enumerate() {
            if let Some(pid) = p.point3d_id
                && !self.points3d.contains_key(&pid)
            {
                return Err(Problem::MissingPoint3D {
                    image_id: image.id,
                    point2d_idx: idx,
                    point3d_id: pid,
                });
            }
        }
        Ok(())
    }

    /// The first point (by id) whose track refers to a missing image or observation.
    pub(crate) fn validate_points(&self) -> Result<(), (u64, Problem)> {
        for (&pid, point) in &self.points3d {
            for t in &point.track {
                let exists = self
                    .images
                    .get(&t.image_id)
                    .is_some_and(|im| (t.point2d_idx as usize) < im.points2d.len());
                if !exists {
                    return Err((
                        pid,
                        Problem::MissingObservation {
                            point3d_id: pid,
                            image_id: t.image_id,
                            point2d_idx: t.point2d_idx,
                        },
                    ));
                }
            }
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn image_names_that_leave_the_images_folder_have_no_relative_file() {
        let image = |name: &str| ImageRecord {
            id: 1,
            qvec: [1.0, 0.0, 0.0, 0.0],
            tvec: [0.0; 3],
            camera_id: 1,
            name: name.into(),
            points2d: Vec::new(),
        };
        for inside in ["a.png", "cam1/a.png", "./a.png", "a..b.png", "..a.png"] {
            assert_eq!(
                image(inside).relative_file(),
                Some(std::path::Path::new(inside)),
                "{inside}"
            );
        }
        for outside in [
            "",
            "../a.png",
            "cam/../../a.png",
            "/etc/passwd",
            "a/..",
            ".",
            "cam/..",
        ] {
            assert_eq!(image(outside).relative_file(), None, "{outside:?}");
        }
    }
}
