//! The PccAppRenderer header comments: `frame_to_world_scale`, `frame_to_world_translation`,
//! `width`, `rig_count` and `rig_matrix_k` (see `docs/reference/formats.md` §1.3, §2.2).

use std::path::Path;

use glam::DVec3;

use crate::{CaptureCamera, Error};

/// What the header comments say about the frame and the capture rig.
#[derive(Debug, Clone, Default, PartialEq)]
pub(crate) struct RigComments {
    /// `frame_to_world_scale s`.
    pub scale: Option<f64>,
    /// `frame_to_world_translation tx ty tz`.
    pub translation: Option<DVec3>,
    /// `width w`.
    pub width: Option<u32>,
    /// `rig_count n` with its header line.
    pub count: Option<(usize, usize)>,
    /// `rig_matrix_k` lines: (k, 16 numbers, header line).
    pub matrices: Vec<(usize, [f64; 16], usize)>,
    /// Every other comment, in order.
    pub other: Vec<String>,
}

/// Most capture cameras a rig comment may declare; far above any real rig (8iVSLF has 13) and
/// small enough that a corrupt `rig_count` cannot make us allocate much.
const MAX_RIG_CAMERAS: usize = 4096;

/// Sorts header comments into rig keys and the rest; malformed rig keys are header errors.
pub(crate) fn parse_rig_comments(
    path: &Path,
    comments: &[(usize, String)],
) -> Result<RigComments, Error> {
    let mut rig = RigComments::default();
    for (line, text) in comments {
        let line = *line;
        let err = |message: String| Error::Header {
            path: path.to_path_buf(),
            line,
            message,
        };
        let mut words = text.split_whitespace();
        let key = words.next().unwrap_or("");
        let values: Vec<&str> = words.collect();
        let numbers = |n: usize| -> Result<Vec<f64>, Error> {
            if values.len() != n {
                return Err(err(format!(
                    "'{key}' needs {n} number(s), found {}",
                    values.len()
                )));
            }
            values
                .iter()
                .map(|v| {
                    v.parse::<f64>()
                        .ok()
                        .filter(|x| x.is_finite())
                        .ok_or_else(|| err(format!("'{key}': {v:?} is not a finite number")))
                })
                .collect()
        };
        match key {
            "frame_to_world_scale" => {
                let s = numbers(1)?[0];
                if s == 0.0 {
                    return Err(err("frame_to_world_scale is 0".into()));
                }
                rig.scale = Some(s);
            }
            "frame_to_world_translation" => {
                let t = numbers(3)?;
                rig.translation = Some(DVec3::new(t[0], t[1], t[2]));
            }
            "width" => {
                let v = values.first().copied().unwrap_or("");
                rig.width = Some(v.parse().ok().filter(|_| values.len() == 1).ok_or_else(
                    || {
                        err(format!(
                            "'width' needs one non-negative integer, found {:?}",
                            values.join(" ")
                        ))
                    },
                )?);
            }
            "rig_count" => {
                let v = values.first().copied().unwrap_or("");
                let n: usize = v
                    .parse()
                    .ok()
                    .filter(|_| values.len() == 1)
                    .ok_or_else(|| {
                        err(format!(
                            "'rig_count' needs one non-negative integer, found {:?}",
                            values.join(" ")
                        ))
                    })?;
                if n > MAX_RIG_CAMERAS {
                    return Err(err(format!(
                        "rig_count {n} exceeds the limit of {MAX_RIG_CAMERAS} cameras"
                    )));
                }
                rig.count = Some((n, line));
            }
            k if k.starts_with("rig_matrix_") => {
                let index: usize = k["rig_matrix_".len()..].parse().map_err(|_| {
                    err(format!("'{k}': camera index is not a non-negative integer"))
                })?;
                let m = numbers(16)?;
                let mut matrix = [0.0; 16];
                matrix.copy_from_slice(&m);
                if rig.matrices.iter().any(|(j, _, _)| *j == index) {
                    return Err(err(format!("camera {index} has two rig_matrix lines")));
                }
                rig.matrices.push((index, matrix, line));
            }
            _ => rig.other.push(text.clone()),
        }
    }
    Ok(rig)
}

impl RigComments {
    /// The capture cameras, checked against `num_cameras` colour sets found in the properties.
    ///
    /// Errors (rather than warnings) because a rig that disagrees with the colours would make
    /// every view-dependent colour silently wrong.
    pub(crate) fn cameras(
        &self,
        path: &Path,
        num_cameras: usize,
    ) -> Result<Vec<CaptureCamera>, Error> {
        let err = |message: String| Error::Rig {
            path: path.to_path_buf(),
            message,
        };
        let declared = match self.count {
            Some((n, line)) => {
                if n != num_cameras {
                    return Err(err(format!(
                        "header line {line}: rig_count is {n} but the vertex element has colours for {num_cameras} camera(s) (red0..red{})",
                        num_cameras.saturating_sub(1)
                    )));
                }
                n
            }
            None if self.matrices.is_empty() => return Ok(Vec::new()),
            None => num_cameras,
        };
        let mut matrices = vec![None; declared];
        for (k, m, line) in &self.matrices {
            match matrices.get_mut(*k) {
                Some(slot) => *slot = Some(*m),
                None => {
                    return Err(err(format!(
                        "header line {line}: rig_matrix_{k} but the rig has only {declared} camera(s) (per-camera colour properties / rig_count)"
                    )));
                }
            }
        }
        let scale = self.scale.unwrap_or(1.0);
        let translation = self.translation.unwrap_or(DVec3::ZERO);
        matrices
            .into_iter()
            .enumerate()
            .map(|(k, m)| {
                let m = m.ok_or_else(|| {
                    err(format!(
                        "camera {k} of {declared} has no rig_matrix_{k} comment"
                    ))
                })?;
                // The renderer takes the camera centre from glm's m[3][0..2] = values 12..14 (§2.2).
                let world = DVec3::new(m[12], m[13], m[14]);
                Ok(CaptureCamera {
                    position: (world - translation) / scale,
                    matrix: Some(m),
                })
            })
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn comments(lines: &[&str]) -> Vec<(usize, String)> {
        lines
            .iter()
            .enumerate()
            .map(|(i, s)| (i + 3, s.to_string()))
            .collect()
    }

    #[test]
    fn camera_centre_is_voxel_position_of_values_12_to_14() {
        let mut m = vec!["1"; 16];
        m[12] = "12.0";
        m[13] = "-3";
        m[14] = "5.5";
        let line = format!("rig_matrix_0 {}", m.join(" "));
        let rig = parse_rig_comments(
            Path::new("a.ply"),
            &comments(&[
                "Version 2",
                "frame_to_world_scale 0.5",
                "frame_to_world_translation 2 1 -0.5",
                "rig_count 1",
                &line,
            ]),
        )
        .unwrap();
        assert_eq!(rig.other, vec!["Version 2".to_string()]);
        let cams = rig.cameras(Path::new("a.ply"), 1).unwrap();
        assert_eq!(cams[0].position, DVec3::new(20.0, -8.0, 12.0));
    }

    #[test]
    fn disagreements_are_errors() {
        let m = format!("rig_matrix_1 {}", vec!["0"; 16].join(" "));
        let rig = parse_rig_comments(Path::new("a.ply"), &comments(&["rig_count 2", &m])).unwrap();
        let e = rig.cameras(Path::new("a.ply"), 2).unwrap_err().to_string();
        assert!(e.contains("camera 0 of 2 has no rig_matrix_0"), "{e}");
        let e = rig.cameras(Path::new("a.ply"), 3).unwrap_err().to_string();
        assert!(
            e.contains("rig_count is 2") && e.contains("3 camera"),
            "{e}"
        );
        let e =
            parse_rig_comments(Path::new("a.ply"), &comments(&["rig_matrix_0 1 2 3"])).unwrap_err();
        assert!(matches!(e, Error::Header { line: 3, .. }), "{e}");
    }
}
