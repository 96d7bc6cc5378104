//! The specular shading model that colours each point towards each capture camera.

use glam::Vec3;

use crate::Error;

/// The specular shading model that makes the per-camera colours (display-space Blinn–Phong).
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct Shading {
    /// Direction towards the (directional, white) light, world axes; normalised on use.
    pub light_direction: [f32; 3],
    /// Ambient term (fraction of the albedo lit regardless of orientation).
    pub ambient: f32,
    /// Diffuse (Lambert) weight.
    pub diffuse: f32,
}

impl Default for Shading {
    fn default() -> Self {
        Self {
            light_direction: [0.4, 1.0, 0.6],
            ambient: 0.25,
            diffuse: 0.75,
        }
    }
}

/// How shiny a surface is.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct Gloss {
    /// Specular weight (0 for matte).
    pub specular: f32,
    /// Blinn–Phong exponent.
    pub shininess: f32,
}

impl Shading {
    /// The view-independent shade: albedo · (ambient + diffuse · max(0, n·l)), clamped to [0, 1].
    pub(crate) fn diffuse_color(&self, normal: Vec3, albedo: [f32; 3]) -> [f32; 3] {
        let l = Vec3::from(self.light_direction).normalize_or_zero();
        let k = self.ambient + self.diffuse * normal.dot(l).max(0.0);
        albedo.map(|a| (a * k).clamp(0.0, 1.0))
    }

    /// The colour seen from direction `to_viewer` (unit): the diffuse shade plus the Blinn–Phong
    /// highlight specular · max(0, n·h)^shininess with h = normalize(l + v), clamped to [0, 1].
    /// Two-sided: the normal is turned towards the viewer.
    pub(crate) fn color(
        &self,
        normal: Vec3,
        to_viewer: Vec3,
        albedo: [f32; 3],
        gloss: Gloss,
    ) -> [f32; 3] {
        let n = if normal.dot(to_viewer) < 0.0 {
            -normal
        } else {
            normal
        };
        let base = self.diffuse_color(n, albedo);
        let l = Vec3::from(self.light_direction).normalize_or_zero();
        let h = (l + to_viewer).normalize_or_zero();
        let s = if n.dot(l) > 0.0 {
            gloss.specular * n.dot(h).max(0.0).powf(gloss.shininess)
        } else {
            0.0
        };
        base.map(|c| (c + s).clamp(0.0, 1.0))
    }

    /// Checks the shading parameters.
    pub(crate) fn validate(&self) -> Result<(), Error> {
        let ok = self.light_direction.iter().all(|v| v.is_finite())
            && Vec3::from(self.light_direction).length() > 0.0
            && self.ambient.is_finite()
            && self.diffuse.is_finite();
        if ok {
            Ok(())
        } else {
            Err(Error::InvalidConfig(format!(
                "bad shading parameters {self:?}"
            )))
        }
    }
}
