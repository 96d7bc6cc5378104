//! SH bands by content: the lowest SH degree whose held-out score stays within a tolerance of
//! the trained degree's, and, per splat, higher bands dropped where they carry no view
//! dependence (a matte splat's bands 1–3 are noise that costs 45 of its 48 colour numbers).

use serde::{Deserialize, Serialize};
use splat_core::{Splats, num_sh_coeffs};

/// What [`choose_bands`] measured and did.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct BandChoice {
    /// The degree the model was trained with.
    pub trained_degree: u32,
    /// The degree kept.
    pub degree: u32,
    /// Held-out PSNR (dB, as the caller's scorer measures it: the pipeline's is
    /// [`crate::Metrics::psnr_both`]) of the trained model rendered at degree 0, 1, … up to its
    /// trained degree.
    pub psnr_by_degree: Vec<f64>,
    /// Splats whose higher bands were set to zero (no view dependence).
    pub flattened: usize,
    /// Held-out PSNR (dB) after flattening them (the kept degree's before it).
    pub psnr_flattened: f64,
}

/// The model with its SH cut to `degree` (the bands above it dropped); a degree at or above the
/// model's returns a copy.
#[must_use]
pub fn with_degree(splats: &Splats, degree: u32) -> Splats {
    if degree >= splats.sh_degree {
        return splats.clone();
    }
    let (k, keep) = (splats.coeffs_per_splat(), num_sh_coeffs(degree));
    let mut out = splats.clone();
    out.sh_degree = degree;
    out.sh = splats
        .sh
        .chunks_exact(k)
        .flat_map(|c| c[..keep].iter().copied())
        .collect();
    out
}

/// The root mean square over all view directions of the colour the bands above 0 add (the
/// largest of the three channels). The real SH basis is orthonormal on the sphere, so the mean
/// of the square is Σ c² / 4π.
#[must_use]
pub fn view_dependence_rms(coeffs: &[[f32; 3]]) -> f32 {
    let mut sums = [0.0_f32; 3];
    for c in coeffs.iter().skip(1) {
        for ch in 0..3 {
            sums[ch] += c[ch] * c[ch];
        }
    }
    let largest = sums.iter().copied().fold(0.0, f32::max);
    (largest / (4.0 * std::f32::consts::PI)).sqrt()
}

/// Sets the bands above 0 of every splat whose [`view_dependence_rms`] is at most `max_rms`
/// to zero; returns how many.
pub fn flatten_static(splats: &mut Splats, max_rms: f32) -> usize {
    let k = splats.coeffs_per_splat();
    if k < 2 {
        return 0;
    }
    let mut count = 0;
    for coeffs in splats.sh.chunks_exact_mut(k) {
        if view_dependence_rms(coeffs) <= max_rms && coeffs[1..].iter().any(|c| *c != [0.0; 3]) {
            coeffs[1..].fill([0.0; 3]);
            count += 1;
        }
    }
    count
}

/// Keeps the lowest degree whose held-out PSNR (`psnr`) is within `tolerance_db` of the trained
/// model's, then flattens the splats with no view dependence above `max_rms` when that too stays
/// within the tolerance of the trained model (else they keep their bands).
///
/// # Errors
/// What `psnr` returns.
pub fn choose_bands<E>(
    splats: &Splats,
    tolerance_db: f64,
    max_rms: f32,
    psnr: &mut dyn FnMut(&Splats) -> Result<f64, E>,
) -> Result<(Splats, BandChoice), E> {
    let trained_degree = splats.sh_degree;
    let full = psnr(splats)?;
    let mut psnr_by_degree = Vec::new();
    for d in 0..trained_degree {
        psnr_by_degree.push(psnr(&with_degree(splats, d))?);
    }
    psnr_by_degree.push(full);
    let floor = full - tolerance_db;
    let degree = psnr_by_degree
        .iter()
        .position(|&p| p >= floor)
        .unwrap_or(trained_degree as usize) as u32;
    let kept = with_degree(splats, degree);
    let mut flat = kept.clone();
    let flattened = flatten_static(&mut flat, max_rms);
    let psnr_flattened = if flattened > 0 {
        psnr(&flat)?
    } else {
        psnr_by_degree[degree as usize]
    };
    let (model, flattened) = if flattened > 0 && psnr_flattened >= floor {
        (flat, flattened)
    } else {
        (kept, 0)
    };
    Ok((
        model,
        BandChoice {
            trained_degree,
            degree,
            psnr_by_degree,
            flattened,
            psnr_flattened,
        },
    ))
}

#[cfg(test)]
mod tests {
    use glam::Vec3;
    use splat_core::sh;

    use super::*;

    fn model() -> Splats {
        let mut s = Splats::new(3);
        for i in 0..3 {
            let mut c = vec![[0.1 * i as f32; 3]; 16];
            // Splat 0: no view dependence at all; 1: a faint one; 2: a strong one.
            let amp = [0.0, 1e-3, 0.3][i];
            for (j, v) in c.iter_mut().enumerate().skip(1) {
                *v = [amp * (j as f32).sin(), amp * 0.5, -amp];
            }
            s.push(Vec3::ZERO, Vec3::ZERO, [1.0, 0.0, 0.0, 0.0], 0.0, &c);
        }
        s
    }

    /// The closed form Σc²/4π against the mean of the squared colour over many directions.
    #[test]
    fn view_dependence_rms_is_the_mean_over_the_sphere() {
        let s = model();
        let coeffs = s.sh_of(2);
        let mut rest = coeffs.to_vec();
        rest[0] = [0.0; 3];
        let n = 200_000;
        let golden = std::f32::consts::PI * (3.0 - 5.0_f32.sqrt());
        let mut sums = [0.0_f64; 3];
        for i in 0..n {
            // Fibonacci sphere: nearly uniform directions.
            let y = 1.0 - 2.0 * (i as f32 + 0.5) / n as f32;
            let r = (1.0 - y * y).sqrt();
            let t = golden * i as f32;
            let v = sh::eval(3, Vec3::new(r * t.cos(), y, r * t.sin()), &rest);
            for ch in 0..3 {
                sums[ch] += f64::from(v[ch] * v[ch]);
            }
        }
        let largest = sums.iter().copied().fold(0.0, f64::max) / n as f64;
        let rms = view_dependence_rms(coeffs);
        assert!(
            (f64::from(rms) - largest.sqrt()).abs() < 1e-3 * largest.sqrt(),
            "{rms} vs {}",
            largest.sqrt()
        );
    }

    #[test]
    fn cutting_a_degree_keeps_the_lower_bands() {
        let s = model();
        let one = with_degree(&s, 1);
        assert_eq!((one.sh_degree, one.coeffs_per_splat()), (1, 4));
        assert_eq!(one.sh_of(2), &s.sh_of(2)[..4]);
        assert!(one.validate().is_ok());
        assert_eq!(with_degree(&s, 3), s);
    }

    #[test]
    fn only_splats_without_view_dependence_are_flattened() {
        let mut s = model();
        let before = s.clone();
        // 1e-3 coefficients give an RMS of about 1e-3; the threshold sits above it.
        assert_eq!(
            flatten_static(&mut s, 2e-3),
            1,
            "splat 0 has nothing to drop"
        );
        assert!(s.sh_of(1)[1..].iter().all(|c| *c == [0.0; 3]));
        assert_eq!(s.sh_of(2), before.sh_of(2));
        assert_eq!(s.sh_of(1)[0], before.sh_of(1)[0]);
    }

    /// The degree is the lowest within the tolerance; a flattening that costs too much is undone.
    #[test]
    fn the_lowest_degree_within_the_tolerance_is_kept() {
        let s = model();
        // PSNR by degree: 30, 39.95, 40, 40 (the scorer reads the degree and the flattening).
        let mut scorer = |m: &Splats| -> Result<f64, ()> {
            let flat = m
                .sh
                .chunks_exact(m.coeffs_per_splat())
                .any(|c| c.len() > 1 && c[1..].iter().all(|v| *v == [0.0; 3]) && c[0] != [0.0; 3]);
            let by_degree = [30.0, 39.95, 40.0, 40.0][m.sh_degree as usize];
            Ok(if flat { by_degree - 0.5 } else { by_degree })
        };
        let (m, c) = choose_bands(&s, 0.1, 2e-3, &mut scorer).unwrap();
        assert_eq!(c.degree, 1);
        assert_eq!(c.psnr_by_degree, vec![30.0, 39.95, 40.0, 40.0]);
        // Flattening splat 1 would cost 0.5 dB: undone.
        assert_eq!(c.flattened, 0);
        assert_eq!(m, with_degree(&s, 1));
        let (m, c) = choose_bands(&s, 1.0, 2e-3, &mut scorer).unwrap();
        assert_eq!((c.degree, c.flattened), (1, 1));
        assert!(m.sh_of(1)[1..].iter().all(|v| *v == [0.0; 3]));
    }
}
