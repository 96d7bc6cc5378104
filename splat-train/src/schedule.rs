//! Learning-rate and SH-degree schedules of Inria's 3DGS trainer.

/// Log-linear interpolation from `init` to `last` over `max_steps` (Inria's `get_expon_lr_func`
/// without the delay, which its trainer leaves inactive): lr(t) = exp((1−s)·ln init + s·ln last),
/// s = clamp(t / max_steps, 0, 1).
#[must_use]
pub fn exponential_lr(init: f32, last: f32, step: u32, max_steps: u32) -> f32 {
    if init <= 0.0 || last <= 0.0 {
        return 0.0;
    }
    let s = if max_steps == 0 {
        1.0
    } else {
        (step as f64 / f64::from(max_steps)).clamp(0.0, 1.0)
    };
    ((1.0 - s) * f64::from(init).ln() + s * f64::from(last).ln()).exp() as f32
}

/// Active SH degree at `iteration` (0-based): one more band every `interval` iterations up to
/// `max_degree` ("Every 1000 its we increase the levels of SH up to a maximum degree", Inria).
#[must_use]
pub fn sh_degree_at(iteration: u32, interval: u32, max_degree: u32) -> u32 {
    if interval == 0 {
        return max_degree;
    }
    (iteration / interval).min(max_degree)
}

/// Scene extent as Inria's `getNerfppNorm`: 1.1 × the largest distance of a camera centre from
/// the mean centre (a single camera gives 1.1 × 0, replaced by 1 so rates stay positive).
#[must_use]
pub fn camera_extent(centres: &[glam::DVec3]) -> f64 {
    if centres.is_empty() {
        return 1.0;
    }
    let mean = centres.iter().copied().sum::<glam::DVec3>() / centres.len() as f64;
    let r = centres.iter().map(|c| c.distance(mean)).fold(0.0, f64::max) * 1.1;
    if r > 0.0 && r.is_finite() { r } else { 1.0 }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn lr_endpoints_and_midpoint_are_geometric() {
        assert!((exponential_lr(1.6e-4, 1.6e-6, 0, 100) - 1.6e-4).abs() < 1e-10);
        assert!((exponential_lr(1.6e-4, 1.6e-6, 100, 100) - 1.6e-6).abs() < 1e-12);
        assert!((exponential_lr(1.6e-4, 1.6e-6, 500, 100) - 1.6e-6).abs() < 1e-12);
        assert!((exponential_lr(1.6e-4, 1.6e-6, 50, 100) - 1.6e-5).abs() < 1e-10);
    }

    #[test]
    fn sh_degree_steps() {
        assert_eq!(sh_degree_at(0, 1000, 3), 0);
        assert_eq!(sh_degree_at(999, 1000, 3), 0);
        assert_eq!(sh_degree_at(1000, 1000, 3), 1);
        assert_eq!(sh_degree_at(9000, 1000, 3), 3);
        assert_eq!(sh_degree_at(5, 0, 2), 2);
    }

    #[test]
    fn extent_of_ring() {
        let c = [
            glam::DVec3::X,
            -glam::DVec3::X,
            glam::DVec3::Y * 2.0,
            -glam::DVec3::Y * 2.0,
        ];
        assert!((camera_extent(&c) - 2.2).abs() < 1e-12);
    }
}
