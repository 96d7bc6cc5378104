//! COLMAP binary format (`cameras.bin`, `images.bin`, `points3D.bin`), little endian, as
//! COLMAP's `reconstruction_io_binary.cc` reads and writes it.
//!
//! Declared counts are checked against the bytes left before anything is allocated, so a
//! corrupt header cannot make the reader reserve more memory than the file could fill.

use std::collections::BTreeMap;
use std::collections::btree_map::Range;
use std::path::Path;

use glam::{DVec2, DVec3};

use crate::error::{Location, Problem};
use crate::located::{ImagesRead, PointsRead};
use crate::reconstruction::CameraField;
use crate::{CameraModel, CameraRecord, Error, ImageRecord, Point2D, Point3D, TrackElement};

/// Bytes of one camera record before its parameters: id u32, model i32, width u64, height u64.
const CAMERA_HEADER: u64 = 24;
/// Minimum bytes of an image record: id, 7 f64, camera id, the name's NUL, the points2D count.
const IMAGE_MIN: u64 = 4 + 56 + 4 + 1 + 8;
/// Bytes of one 2D point: x, y (f64) and point3D id (u64).
pub(crate) const POINT2D_SIZE: u64 = 24;
/// Minimum bytes of a 3D point record: id, xyz, rgb, error, track length.
const POINT3D_MIN: u64 = 8 + 24 + 3 + 8 + 8;
/// Bytes of one track element: image id and point2D index (u32 each).
const TRACK_ELEMENT_SIZE: u64 = 8;
/// The point3D id that means "no 3D point" (−1 as u64).
const INVALID_POINT3D_ID: u64 = u64::MAX;

/// A cursor over a file's bytes that reports errors at byte offsets.
struct Reader<'a> {
    path: &'a Path,
    data: &'a [u8],
    pos: usize,
}

impl<'a> Reader<'a> {
    fn offset(&self) -> u64 {
        self.pos as u64
    }

    fn left(&self) -> u64 {
        (self.data.len() - self.pos) as u64
    }

    fn error_at(&self, offset: u64, problem: Problem) -> Error {
        Error::Format {
            path: self.path.to_path_buf(),
            location: Location::Offset(offset),
            problem,
        }
    }

    fn bytes<const N: usize>(&mut self) -> Result<[u8; N], Error> {
        let slice = self.data.get(self.pos..self.pos + N).ok_or_else(|| {
            self.error_at(
                self.offset(),
                Problem::Truncated {
                    needed: N as u64,
                    available: self.left(),
                },
            )
        })?;
        self.pos += N;
        let mut out = [0u8; N];
        out.copy_from_slice(slice);
        Ok(out)
    }

    fn u8(&mut self) -> Result<u8, Error> {
        Ok(self.bytes::<1>()?[0])
    }

    fn u32(&mut self) -> Result<u32, Error> {
        self.bytes().map(u32::from_le_bytes)
    }

    fn i32(&mut self) -> Result<i32, Error> {
        self.bytes().map(i32::from_le_bytes)
    }

    fn u64(&mut self) -> Result<u64, Error> {
        self.bytes().map(u64::from_le_bytes)
    }

    fn f64(&mut self) -> Result<f64, Error> {
        self.bytes().map(f64::from_le_bytes)
    }

    /// Reads a count and checks that `count · min_size` bytes are left.
    fn count(&mut self, what: &'static str, min_size: u64) -> Result<u64, Error> {
        let at = self.offset();
        let count = self.u64()?;
        let needed = u128::from(count) * u128::from(min_size);
        if needed > u128::from(self.left()) {
            return Err(self.error_at(
                at,
                Problem::CountTooLarge {
                    what,
                    count,
                    needed,
                    available: self.left(),
                },
            ));
        }
        Ok(count)
    }

    /// Reads a NUL-terminated UTF-8 string.
    fn c_string(&mut self) -> Result<String, Error> {
        let at = self.offset();
        let rest = &self.data[self.pos..];
        let len = rest.iter().position(|&b| b == 0).ok_or_else(|| {
            self.error_at(
                at,
                Problem::Malformed("image name has no terminating NUL byte".into()),
            )
        })?;
        let name = std::str::from_utf8(&rest[..len])
            .map_err(|_| {
                self.error_at(
                    at,
                    Problem::Malformed("image name is not valid UTF-8".into()),
                )
            })?
            .to_string();
        self.pos += len + 1;
        Ok(name)
    }

    fn finish(&self) -> Result<(), Error> {
        if self.left() == 0 {
            Ok(())
        } else {
            Err(self.error_at(
                self.offset(),
                Problem::Malformed(format!("{} bytes after the last record", self.left())),
            ))
        }
    }
}

fn read_file(path: &Path) -> Result<Vec<u8>, Error> {
    std::fs::read(path).map_err(|e| Error::io(path, e))
}

/// Reads `cameras.bin`.
pub(crate) fn read_cameras(path: &Path) -> Result<BTreeMap<u32, CameraRecord>, Error> {
    let data = read_file(path)?;
    let mut r = Reader {
        path,
        data: &data,
        pos: 0,
    };
    let n = r.count("camera", CAMERA_HEADER)?;
    let mut cameras = BTreeMap::new();
    for _ in 0..n {
        let at = r.offset();
        let id = r.u32()?;
        let model_at = r.offset();
        let model_id = r.i32()?;
        let model = CameraModel::from_id(model_id)
            .ok_or_else(|| r.error_at(model_at, Problem::UnknownModel(format!("id {model_id}"))))?;
        let width = r.u64()?;
        let height = r.u64()?;
        let params = (0..model.num_params())
            .map(|_| r.f64())
            .collect::<Result<Vec<_>, _>>()?;
        let camera = CameraRecord {
            id,
            model,
            width,
            height,
            params,
        };
        if let Some((field, problem)) = camera.bad_intrinsics() {
            // The record: CAMERA_ID (4 bytes), MODEL_ID (4), WIDTH (8), HEIGHT (8), PARAMS.
            let offset = match field {
                CameraField::Width => 8,
                CameraField::Height => 16,
                CameraField::Param(i) => CAMERA_HEADER + 8 * i as u64,
            };
            return Err(r.error_at(at + offset, problem));
        }
        if cameras.insert(id, camera).is_some() {
            return Err(r.error_at(
                at,
                Problem::DuplicateId {
                    what: "camera",
                    id: id.into(),
                },
            ));
        }
    }
    r.finish()?;
    Ok(cameras)
}

/// Reads `images.bin`.
pub(crate) fn read_images(path: &Path) -> Result<ImagesRead, Error> {
    let data = read_file(path)?;
    let mut r = Reader {
        path,
        data: &data,
        pos: 0,
    };
    let n = r.count("image", IMAGE_MIN)?;
    let mut out = ImagesRead::default();
    for _ in 0..n {
        let at = r.offset();
        let id = r.u32()?;
        let qvec = [r.f64()?, r.f64()?, r.f64()?, r.f64()?];
        let tvec = [r.f64()?, r.f64()?, r.f64()?];
        let camera_id = r.u32()?;
        let name = r.c_string()?;
        let num_points = r.count("points2D", POINT2D_SIZE)?;
        let points_at = r.offset();
        let points2d = (0..num_points)
            .map(|_| {
                let xy = DVec2::new(r.f64()?, r.f64()?);
                let pid = r.u64()?;
                Ok(Point2D {
                    xy,
                    point3d_id: (pid != INVALID_POINT3D_ID).then_some(pid),
                })
            })
            .collect::<Result<Vec<_>, Error>>()?;
        let image = ImageRecord {
            id,
            qvec,
            tvec,
            camera_id,
            name,
            points2d,
        };
        if let Some((i, problem)) = image.bad_pose() {
            // The pose follows the 4-byte image id: QW QX QY QZ TX TY TZ, 8 bytes each.
            return Err(r.error_at(at + 4 + 8 * i as u64, problem));
        }
        out.add(image, Location::Offset(at), Location::Offset(points_at))
            .map_err(|p| r.error_at(at, p))?;
    }
    r.finish()?;
    Ok(out)
}

/// Reads `points3D.bin`.
pub(crate) fn read_points3d(path: &Path) -> Result<PointsRead, Error> {
    let data = read_file(path)?;
    let mut r = Reader {
        path,
        data: &data,
        pos: 0,
    };
    let n = r.count("point3D", POINT3D_MIN)?;
    let mut out = PointsRead::default();
    for _ in 0..n {
        let at = r.offset();
        let id = r.u64()?;
        let xyz = DVec3::new(r.f64()?, r.f64()?, r.f64()?);
        let rgb = [r.u8()?, r.u8()?, r.u8()?];
        let error = r.f64()?;
        let len = r.count("track element", TRACK_ELEMENT_SIZE)?;
        let track = (0..len)
            .map(|_| {
                Ok(TrackElement {
                    image_id: r.u32()?,
                    point2d_idx: r.u32()?,
                })
            })
            .collect::<Result<Vec<_>, Error>>()?;
        let point = Point3D {
            xyz,
            rgb,
            error,
            track,
        };
        if let Some((i, problem)) = point.non_finite(id) {
            // X Y Z follow the 8-byte point id.
            return Err(r.error_at(at + 8 + 8 * i as u64, problem));
        }
        if out.points.insert(id, point).is_some() {
            return Err(r.error_at(
                at,
                Problem::DuplicateId {
                    what: "point3D",
                    id,
                },
            ));
        }
        out.location.insert(id, Location::Offset(at));
    }
    r.finish()?;
    Ok(out)
}

fn put_u64(out: &mut Vec<u8>, v: u64) {
    out.extend_from_slice(&v.to_le_bytes());
}

fn put_f64(out: &mut Vec<u8>, v: f64) {
    out.extend_from_slice(&v.to_le_bytes());
}

/// Bytes of `cameras.bin`.
pub(crate) fn cameras_bytes(cameras: &BTreeMap<u32, CameraRecord>) -> Vec<u8> {
    let mut out = Vec::new();
    put_u64(&mut out, cameras.len() as u64);
    for c in cameras.values() {
        out.extend_from_slice(&c.id.to_le_bytes());
        out.extend_from_slice(&c.model.id().to_le_bytes());
        put_u64(&mut out, c.width);
        put_u64(&mut out, c.height);
        for &p in &c.params {
            put_f64(&mut out, p);
        }
    }
    out
}

/// Bytes of `images.bin`; names must not contain NUL (checked by the caller).
pub(crate) fn images_bytes(images: &BTreeMap<u32, ImageRecord>) -> Vec<u8> {
    let mut out = Vec::new();
    put_u64(&mut out, images.len() as u64);
    for im in images.values() {
        out.extend_from_slice(&im.id.to_le_bytes());
        for &v in im.qvec.iter().chain(&im.tvec) {
            put_f64(&mut out, v);
        }
        out.extend_from_slice(&im.camera_id.to_le_bytes());
        out.extend_from_slice(im.name.as_bytes());
        out.push(0);
        put_u64(&mut out, im.points2d.len() as u64);
        for p in &im.points2d {
            put_f64(&mut out, p.xy.x);
            put_f64(&mut out, p.xy.y);
            put_u64(&mut out, p.point3d_id.unwrap_or(INVALID_POINT3D_ID));
        }
    }
    out
}

/// The head of `points3D.bin`: the number of points. The records follow, encoded by
/// [`points3d_records`] ([`crate::io::write_points`]).
pub(crate) fn points3d_head(points: &BTreeMap<u64, Point3D>) -> Vec<u8> {
    let mut count = Vec::new();
    put_u64(&mut count, points.len() as u64);
    count
}

/// Bytes of the `points3D.bin` records of a run of points, in id order.
pub(crate) fn points3d_records(run: Range<'_, u64, Point3D>) -> Vec<u8> {
    let (records, tracks) = run
        .clone()
        .fold((0, 0), |(n, t), (_, p)| (n + 1, t + p.track.len()));
    let mut out =
        Vec::with_capacity(records * POINT3D_MIN as usize + tracks * TRACK_ELEMENT_SIZE as usize);
    for (&id, p) in run {
        put_u64(&mut out, id);
        for v in p.xyz.to_array() {
            put_f64(&mut out, v);
        }
        out.extend_from_slice(&p.rgb);
        put_f64(&mut out, p.error);
        put_u64(&mut out, p.track.len() as u64);
        for t in &p.track {
            out.extend_from_slice(&t.image_id.to_le_bytes());
            out.extend_from_slice(&t.point2d_idx.to_le_bytes());
        }
    }
    out
}
