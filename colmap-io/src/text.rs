//! COLMAP text format (`cameras.txt`, `images.txt`, `points3D.txt`), as COLMAP's
//! `reconstruction_io_text.cc` reads and writes it.
//!
//! Floats are written in Rust's shortest round-trip form, so text → value → text and
//! text ↔ binary conversions are exact.

use std::collections::BTreeMap;
use std::collections::btree_map::Range;
use std::fmt::Write as _;
use std::path::Path;
use std::str::FromStr;

use glam::{DVec2, DVec3};

use crate::error::{Location, Problem};
use crate::located::{ImagesRead, PointsRead};
use crate::{CameraModel, CameraRecord, Error, ImageRecord, Point2D, Point3D, TrackElement};

/// Reads a whole text file, reporting invalid UTF-8 at its line.
fn read_text(path: &Path) -> Result<String, Error> {
    let bytes = std::fs::read(path).map_err(|e| Error::io(path, e))?;
    String::from_utf8(bytes).map_err(|e| {
        let valid = e.utf8_error().valid_up_to();
        let line = e.as_bytes()[..valid]
            .iter()
            .filter(|&&b| b == b'\n')
            .count()
            + 1;
        format_error(
            path,
            line,
            Problem::Malformed("the text is not valid UTF-8".into()),
        )
    })
}

fn format_error(path: &Path, line: usize, problem: Problem) -> Error {
    Error::Format {
        path: path.to_path_buf(),
        location: Location::Line(line),
        problem,
    }
}

/// Whitespace-separated fields of one line, parsed one by one with named errors.
struct Fields<'a>(std::str::SplitWhitespace<'a>);

impl<'a> Fields<'a> {
    fn new(line: &'a str) -> Self {
        Self(line.split_whitespace())
    }

    fn next_str(&mut self, field: &'static str) -> Result<&'a str, Problem> {
        self.0.next().ok_or(Problem::Missing(field))
    }

    fn next<T: FromStr>(&mut self, field: &'static str) -> Result<T, Problem> {
        let token = self.next_str(field)?;
        token.parse().map_err(|_| Problem::Parse {
            field,
            token: token.to_string(),
        })
    }

    fn rest(self) -> Vec<&'a str> {
        self.0.collect()
    }
}

fn parse<T: FromStr>(token: &str, field: &'static str) -> Result<T, Problem> {
    token.parse().map_err(|_| Problem::Parse {
        field,
        token: token.to_string(),
    })
}

/// Lines that hold data: not empty and not comments, with their 1-based numbers.
fn data_lines(text: &str) -> impl Iterator<Item = (usize, &str)> {
    text.lines()
        .enumerate()
        .map(|(i, l)| (i + 1, l.trim()))
        .filter(|(_, l)| !l.is_empty() && !l.starts_with('#'))
}

/// Reads `cameras.txt`.
pub(crate) fn read_cameras(path: &Path) -> Result<BTreeMap<u32, CameraRecord>, Error> {
    let text = read_text(path)?;
    let mut cameras = BTreeMap::new();
    for (n, line) in data_lines(&text) {
        let camera = parse_camera(line).map_err(|p| format_error(path, n, p))?;
        let id = camera.id;
        if cameras.insert(id, camera).is_some() {
            return Err(format_error(
                path,
                n,
                Problem::DuplicateId {
                    what: "camera",
                    id: id.into(),
                },
            ));
        }
    }
    Ok(cameras)
}

fn parse_camera(line: &str) -> Result<CameraRecord, Problem> {
    let mut f = Fields::new(line);
    let id = f.next("CAMERA_ID")?;
    let name = f.next_str("MODEL")?;
    let model =
        CameraModel::from_name(name).ok_or_else(|| Problem::UnknownModel(name.to_string()))?;
    let width = f.next("WIDTH")?;
    let height = f.next("HEIGHT")?;
    let params = f
        .rest()
        .into_iter()
        .map(|t| parse::<f64>(t, "PARAMS"))
        .collect::<Result<Vec<_>, _>>()?;
    if params.len() != model.num_params() {
        return Err(Problem::ParamCount {
            model: model.name(),
            expected: model.num_params(),
            found: params.len(),
        });
    }
    let camera = CameraRecord {
        id,
        model,
        width,
        height,
        params,
    };
    match camera.bad_intrinsics() {
        Some((_, problem)) => Err(problem),
        None => Ok(camera),
    }
}

/// Reads `images.txt`: each data line is followed by its POINTS2D line, which may be empty
/// (COLMAP reads the next line unconditionally). A missing POINTS2D line at the very end of
/// the file is read as empty.
pub(crate) fn read_images(path: &Path) -> Result<ImagesRead, Error> {
    let text = read_text(path)?;
    let mut out = ImagesRead::default();
    let mut lines = text.lines().enumerate().map(|(i, l)| (i + 1, l.trim()));
    while let Some((n, line)) = lines.next() {
        if line.is_empty() || line.starts_with('#') {
            continue;
        }
        let mut image = parse_image(line).map_err(|p| format_error(path, n, p))?;
        let (pn, points_line) = lines.next().unwrap_or((n + 1, ""));
        image.points2d = parse_points2d(points_line).map_err(|p| format_error(path, pn, p))?;
        out.add(image, Location::Line(n), Location::Line(pn))
            .map_err(|p| format_error(path, n, p))?;
    }
    Ok(out)
}

fn parse_image(line: &str) -> Result<ImageRecord, Problem> {
    let mut f = Fields::new(line);
    let id = f.next("IMAGE_ID")?;
    let qvec = [f.next("QW")?, f.next("QX")?, f.next("QY")?, f.next("QZ")?];
    let tvec = [f.next("TX")?, f.next("TY")?, f.next("TZ")?];
    let camera_id = f.next("CAMERA_ID")?;
    let name = f.next_str("NAME")?.to_string();
    let extra = f.rest();
    if !extra.is_empty() {
        return Err(Problem::Malformed(format!(
            "unexpected `{}` after the image name (names cannot contain spaces)",
            extra.join(" ")
        )));
    }
    let image = ImageRecord {
        id,
        qvec,
        tvec,
        camera_id,
        name,
        points2d: Vec::new(),
    };
    match image.bad_pose() {
        Some((_, problem)) => Err(problem),
        None => Ok(image),
    }
}

fn parse_points2d(line: &str) -> Result<Vec<Point2D>, Problem> {
    let tokens: Vec<&str> = line.split_whitespace().collect();
    if !tokens.len().is_multiple_of(3) {
        return Err(Problem::Malformed(format!(
            "POINTS2D has {} numbers, not a multiple of 3 (X, Y, POINT3D_ID)",
            tokens.len()
        )));
    }
    tokens
        .chunks_exact(3)
        .map(|c| {
            let xy = DVec2::new(parse(c[0], "X")?, parse(c[1], "Y")?);
            let id: i64 = parse(c[2], "POINT3D_ID")?;
            let point3d_id = match id {
                -1 => None,
                id => Some(u64::try_from(id).map_err(|_| Problem::Parse {
                    field: "POINT3D_ID",
                    token: c[2].to_string(),
                })?),
            };
            Ok(Point2D { xy, point3d_id })
        })
        .collect()
}

/// Reads `points3D.txt`; a line may have an empty track.
pub(crate) fn read_points3d(path: &Path) -> Result<PointsRead, Error> {
    let text = read_text(path)?;
    let mut out = PointsRead::default();
    for (n, line) in data_lines(&text) {
        let (id, point) = parse_point3d(line).map_err(|p| format_error(path, n, p))?;
        if out.points.insert(id, point).is_some() {
            return Err(format_error(
                path,
                n,
                Problem::DuplicateId {
                    what: "point3D",
                    id,
                },
            ));
        }
        out.location.insert(id, Location::Line(n));
    }
    Ok(out)
}

fn parse_point3d(line: &str) -> Result<(u64, Point3D), Problem> {
    let mut f = Fields::new(line);
    let id = f.next("POINT3D_ID")?;
    let xyz = DVec3::new(f.next("X")?, f.next("Y")?, f.next("Z")?);
    let rgb = [f.next("R")?, f.next("G")?, f.next("B")?];
    let error = f.next("ERROR")?;
    let rest = f.rest();
    if !rest.len().is_multiple_of(2) {
        return Err(Problem::Malformed(format!(
            "TRACK has {} numbers, not pairs of (IMAGE_ID, POINT2D_IDX)",
            rest.len()
        )));
    }
    let track = rest
        .chunks_exact(2)
        .map(|c| {
            Ok(TrackElement {
                image_id: parse(c[0], "IMAGE_ID")?,
                point2d_idx: parse(c[1], "POINT2D_IDX")?,
            })
        })
        .collect::<Result<_, Problem>>()?;
    let point = Point3D {
        xyz,
        rgb,
        error,
        track,
    };
    match point.non_finite(id) {
        Some((_, problem)) => Err(problem),
        None => Ok((id, point)),
    }
}

/// Appends a float in its shortest exact form; exponent notation only for very small or very
/// large magnitudes so lines stay short (both forms parse exactly in C++, Python and Rust).
///
/// The digits come from `zmij` (Schubfach), about six times faster than `core::fmt` on the
/// 17-digit values a cloud's f32 coordinates become in f64, which made `points3D.txt` of a 3M-point
/// frame take a second. Both give the shortest digits that parse back exactly, and the text
/// keeps Rust's spelling of them ("1" not "1.0", "1e300" not "1e+300"), so a file is what `{x}`
/// / `{x:e}` wrote except, rarely, the last digit of a value that lies exactly halfway between
/// two shortest spellings (a test compares the two over random bit patterns).
fn push_f64(out: &mut String, x: f64) {
    if !x.is_finite() {
        // `write!` into a String cannot fail.
        let _ = write!(out, "{x}");
        return;
    }
    let mut buffer = zmij::Buffer::new();
    let digits = buffer.format_finite(x);
    match digits.split_once("e+") {
        Some((mantissa, exponent)) => {
            out.push_str(mantissa);
            out.push('e');
            out.push_str(exponent);
        }
        None => out.push_str(digits.strip_suffix(".0").unwrap_or(digits)),
    }
}

/// Text of `cameras.txt`.
pub(crate) fn cameras_text(cameras: &BTreeMap<u32, CameraRecord>) -> String {
    let mut s = String::from(
        "# Camera list with one line of data per camera:\n#   CAMERA_ID, MODEL, WIDTH, HEIGHT, PARAMS[]\n",
    );
    let _ = writeln!(s, "# Number of cameras: {}", cameras.len());
    for c in cameras.values() {
        let _ = write!(s, "{} {} {} {}", c.id, c.model.name(), c.width, c.height);
        for &p in &c.params {
            s.push(' ');
            push_f64(&mut s, p);
        }
        s.push('\n');
    }
    s
}

/// Text of `images.txt`, with the (possibly empty) POINTS2D line after every image line.
pub(crate) fn images_text(images: &BTreeMap<u32, ImageRecord>) -> Result<String, Problem> {
    let num_obs: usize = images
        .values()
        .map(|im| {
            im.points2d
                .iter()
                .filter(|p| p.point3d_id.is_some())
                .count()
        })
        .sum();
    let mean = if images.is_empty() {
        0.0
    } else {
        num_obs as f64 / images.len() as f64
    };
    let mut s = String::from(
        "# Image list with two lines of data per image:\n#   IMAGE_ID, QW, QX, QY, QZ, TX, TY, TZ, CAMERA_ID, NAME\n#   POINTS2D[] as (X, Y, POINT3D_ID)\n",
    );
    let _ = writeln!(
        s,
        "# Number of images: {}, mean observations per image: {mean}",
        images.len()
    );
    for im in images.values() {
        if im.name.is_empty() || im.name.chars().any(char::is_whitespace) {
            return Err(Problem::BadName(im.name.clone()));
        }
        let _ = write!(s, "{}", im.id);
        for &v in im.qvec.iter().chain(&im.tvec) {
            s.push(' ');
            push_f64(&mut s, v);
        }
        let _ = writeln!(s, " {} {}", im.camera_id, im.name);
        for (k, p) in im.points2d.iter().enumerate() {
            if k > 0 {
                s.push(' ');
            }
            push_f64(&mut s, p.xy.x);
            s.push(' ');
            push_f64(&mut s, p.xy.y);
            match p.point3d_id {
                Some(id) => {
                    let _ = write!(s, " {id}");
                }
                None => s.push_str(" -1"),
            }
        }
        s.push('\n');
    }
    Ok(s)
}

/// The header of `points3D.txt`. The point lines follow, formatted by [`points3d_lines`]
/// ([`crate::io::write_points`]).
pub(crate) fn points3d_head(points: &BTreeMap<u64, Point3D>) -> Vec<u8> {
    let total: usize = points.values().map(|p| p.track.len()).sum();
    let mean = if points.is_empty() {
        0.0
    } else {
        total as f64 / points.len() as f64
    };
    let mut header = String::from(
        "# 3D point list with one line of data per point:\n#   POINT3D_ID, X, Y, Z, R, G, B, ERROR, TRACK[] as (IMAGE_ID, POINT2D_IDX)\n",
    );
    let _ = writeln!(
        header,
        "# Number of points: {}, mean track length: {mean}",
        points.len()
    );
    header.into_bytes()
}

/// The `points3D.txt` lines of a run of points, in id order.
pub(crate) fn points3d_lines(run: Range<'_, u64, Point3D>) -> Vec<u8> {
    let mut s = String::new();
    for (&id, p) in run {
        push_point3d_line(&mut s, id, p);
    }
    s.into_bytes()
}

/// One line of `points3D.txt`. Integers go through `itoa` rather than `write!`: with the floats
/// fast, `core::fmt`'s machinery around each integer was most of a line's time.
fn push_point3d_line(s: &mut String, id: u64, p: &Point3D) {
    let mut integer = itoa::Buffer::new();
    s.push_str(integer.format(id));
    for v in p.xyz.to_array() {
        s.push(' ');
        push_f64(s, v);
    }
    for c in p.rgb {
        s.push(' ');
        s.push_str(integer.format(c));
    }
    s.push(' ');
    push_f64(s, p.error);
    for t in &p.track {
        s.push(' ');
        s.push_str(integer.format(t.image_id));
        s.push(' ');
        s.push_str(integer.format(t.point2d_idx));
    }
    s.push('\n');
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn floats_are_written_exactly_and_parse_back() {
        for x in [
            0.0,
            -0.0,
            1.0,
            0.1,
            1e-7,
            123456.789,
            1e300,
            -2.5e-300,
            f64::MIN_POSITIVE,
            959.5,
        ] {
            let mut s = String::new();
            push_f64(&mut s, x);
            assert_eq!(s.parse::<f64>().unwrap().to_bits(), x.to_bits(), "{s}");
            assert!(s.len() < 30, "{s}");
        }
    }

    /// What `push_f64` wrote before it used zmij: Rust's own shortest forms.
    fn push_f64_core_fmt(out: &mut String, x: f64) {
        let a = x.abs();
        let _ = if a != 0.0 && a.is_finite() && !(1e-5..1e16).contains(&a) {
            write!(out, "{x:e}")
        } else {
            write!(out, "{x}")
        };
    }

    #[test]
    fn floats_are_exact_and_as_short_as_core_fmt_spells_them() {
        let mut state = 0x9e37_79b9_7f4a_7c15_u64;
        let mut next = || {
            // splitmix64: every bit pattern reachable, so every exponent and subnormals too.
            state = state.wrapping_add(0x9e37_79b9_7f4a_7c15);
            let mut z = state;
            z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
            z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
            z ^ (z >> 31)
        };
        let edges = [
            0.0,
            -0.0,
            1.0,
            -1.0,
            1e-5,
            0.999_999_999_999_999_9e-5,
            1e16,
            9_999_999_999_999_998.0,
            f64::MIN_POSITIVE,
            f64::MAX,
            f64::MIN,
            5e-324,
            f64::INFINITY,
            f64::NEG_INFINITY,
            f64::NAN,
        ];
        let bits: Vec<f64> = (0..200_000).map(|_| f64::from_bits(next())).collect();
        // A cloud's coordinates: f32 values widened to f64 (17 digits), and small integers.
        let widened: Vec<f64> = (0..200_000)
            .map(|_| f64::from(f32::from_bits(next() as u32)))
            .collect();
        let integers = (-1000..1000).map(f64::from);
        let mut differing = 0;
        for x in edges.into_iter().chain(bits).chain(widened).chain(integers) {
            let (mut ours, mut core) = (String::new(), String::new());
            push_f64(&mut ours, x);
            push_f64_core_fmt(&mut core, x);
            if x.is_nan() {
                assert_eq!(ours, "NaN");
                continue;
            }
            // Exact, and as short as core's; the last digit may differ only where the value
            // lies exactly halfway between two shortest spellings (e.g. …862.25 as …862.2 or
            // …862.3), about one value in a thousand among these.
            assert_eq!(
                ours.parse::<f64>().map(f64::to_bits),
                Ok(x.to_bits()),
                "{ours}"
            );
            assert_eq!(ours.len(), core.len(), "{ours} against {core}");
            if ours != core {
                differing += 1;
                let tail = |s: &str| s.len() - 1;
                assert_eq!(
                    ours[..tail(&ours)],
                    core[..tail(&core)],
                    "{ours} against {core}"
                );
            }
        }
        assert!(
            differing < 1_000,
            "{differing} spellings differ from core's"
        );
    }

    #[test]
    fn camera_line_errors_name_the_problem() {
        assert_eq!(
            parse_camera("1 PINHOLE 10 10 1 2 3"),
            Err(Problem::ParamCount {
                model: "PINHOLE",
                expected: 4,
                found: 3
            })
        );
        assert_eq!(
            parse_camera("1 PINHOLEX 10 10 1 2 3 4"),
            Err(Problem::UnknownModel("PINHOLEX".into()))
        );
        assert!(matches!(
            parse_camera("1 PINHOLE 10"),
            Err(Problem::Missing("HEIGHT"))
        ));
        assert!(matches!(
            parse_camera("x PINHOLE 10 10 1 2 3 4"),
            Err(Problem::Parse {
                field: "CAMERA_ID",
                ..
            })
        ));
    }

    #[test]
    fn points2d_line_reads_minus_one_as_none() {
        let p = parse_points2d("1.5 2.5 -1 3 4 7").unwrap();
        assert_eq!(p[0].point3d_id, None);
        assert_eq!(p[1].point3d_id, Some(7));
        assert!(parse_points2d("").unwrap().is_empty());
        assert!(matches!(parse_points2d("1 2"), Err(Problem::Malformed(_))));
        assert!(matches!(
            parse_points2d("1 2 -2"),
            Err(Problem::Parse { .. })
        ));
    }
}
