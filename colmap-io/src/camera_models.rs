//! COLMAP camera models: ids, names and parameter counts (`src/colmap/sensor/models.h`).

use std::fmt;

/// A COLMAP camera model; the discriminant is COLMAP's model id.
#[derive(
    Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord, serde::Serialize, serde::Deserialize,
)]
#[allow(missing_docs)] // the variant names are COLMAP's model names
pub enum CameraModel {
    SimplePinhole = 0,
    Pinhole = 1,
    SimpleRadial = 2,
    Radial = 3,
    OpenCv = 4,
    OpenCvFisheye = 5,
    FullOpenCv = 6,
    Fov = 7,
    SimpleRadialFisheye = 8,
    RadialFisheye = 9,
    ThinPrismFisheye = 10,
    RadTanThinPrismFisheye = 11,
    SimpleDivision = 12,
    Division = 13,
    SimpleFisheye = 14,
    Fisheye = 15,
    Eucm = 16,
    Equirectangular = 17,
}

/// (model, name, parameter names) for every model, in id order.
const TABLE: [(CameraModel, &str, &[&str]); 18] = {
    use CameraModel::*;
    [
        (SimplePinhole, "SIMPLE_PINHOLE", &["f", "cx", "cy"]),
        (Pinhole, "PINHOLE", &["fx", "fy", "cx", "cy"]),
        (SimpleRadial, "SIMPLE_RADIAL", &["f", "cx", "cy", "k"]),
        (Radial, "RADIAL", &["f", "cx", "cy", "k1", "k2"]),
        (
            OpenCv,
            "OPENCV",
            &["fx", "fy", "cx", "cy", "k1", "k2", "p1", "p2"],
        ),
        (
            OpenCvFisheye,
            "OPENCV_FISHEYE",
            &["fx", "fy", "cx", "cy", "k1", "k2", "k3", "k4"],
        ),
        (
            FullOpenCv,
            "FULL_OPENCV",
            &[
                "fx", "fy", "cx", "cy", "k1", "k2", "p1", "p2", "k3", "k4", "k5", "k6",
            ],
        ),
        (Fov, "FOV", &["fx", "fy", "cx", "cy", "omega"]),
        (
            SimpleRadialFisheye,
            "SIMPLE_RADIAL_FISHEYE",
            &["f", "cx", "cy", "k"],
        ),
        (
            RadialFisheye,
            "RADIAL_FISHEYE",
            &["f", "cx", "cy", "k1", "k2"],
        ),
        (
            ThinPrismFisheye,
            "THIN_PRISM_FISHEYE",
            &[
                "fx", "fy", "cx", "cy", "k1", "k2", "p1", "p2", "k3", "k4", "sx1", "sy1",
            ],
        ),
        (
            RadTanThinPrismFisheye,
            "RAD_TAN_THIN_PRISM_FISHEYE",
            &[
                "fx", "fy", "cx", "cy", "k0", "k1", "k2", "k3", "k4", "k5", "p0", "p1", "s0", "s1",
                "s2", "s3",
            ],
        ),
        (SimpleDivision, "SIMPLE_DIVISION", &["f", "cx", "cy", "k"]),
        (Division, "DIVISION", &["fx", "fy", "cx", "cy", "k"]),
        (SimpleFisheye, "SIMPLE_FISHEYE", &["f", "cx", "cy"]),
        (Fisheye, "FISHEYE", &["fx", "fy", "cx", "cy"]),
        (Eucm, "EUCM", &["fx", "fy", "cx", "cy", "alpha", "beta"]),
        (Equirectangular, "EQUIRECTANGULAR", &["w", "h"]),
    ]
};

impl CameraModel {
    /// Every model in id order.
    pub const ALL: [CameraModel; 18] = {
        let mut all = [CameraModel::SimplePinhole; 18];
        let mut i = 0;
        while i < 18 {
            all[i] = TABLE[i].0;
            i += 1;
        }
        all
    };

    /// COLMAP's numeric model id (as stored in cameras.bin).
    #[must_use]
    pub fn id(self) -> i32 {
        self as i32
    }

    /// COLMAP's model name (as written in cameras.txt).
    #[must_use]
    pub fn name(self) -> &'static str {
        TABLE[self as usize].1
    }

    /// Names of the parameters, in file order.
    #[must_use]
    pub fn param_names(self) -> &'static [&'static str] {
        TABLE[self as usize].2
    }

    /// Number of parameters the model takes.
    #[must_use]
    pub fn num_params(self) -> usize {
        self.param_names().len()
    }

    /// The model with a numeric id, if COLMAP defines it.
    #[must_use]
    pub fn from_id(id: i32) -> Option<Self> {
        usize::try_from(id)
            .ok()
            .and_then(|i| TABLE.get(i))
            .map(|e| e.0)
    }

    /// The model with a name, if COLMAP defines it.
    #[must_use]
    pub fn from_name(name: &str) -> Option<Self> {
        TABLE.iter().find(|e| e.1 == name).map(|e| e.0)
    }
}

impl fmt::Display for CameraModel {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ids_names_and_counts_are_consistent() {
        for (i, m) in CameraModel::ALL.iter().enumerate() {
            assert_eq!(m.id(), i as i32);
            assert_eq!(CameraModel::from_id(m.id()), Some(*m));
            assert_eq!(CameraModel::from_name(m.name()), Some(*m));
        }
        assert_eq!(CameraModel::SimplePinhole.num_params(), 3);
        assert_eq!(CameraModel::Pinhole.num_params(), 4);
        assert_eq!(CameraModel::OpenCv.num_params(), 8);
        assert_eq!(CameraModel::FullOpenCv.num_params(), 12);
        assert_eq!(CameraModel::RadTanThinPrismFisheye.num_params(), 16);
        assert_eq!(CameraModel::from_id(18), None);
        assert_eq!(CameraModel::from_id(-1), None);
        assert_eq!(CameraModel::from_name("pinhole"), None);
    }
}
