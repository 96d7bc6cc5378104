//! CPU trainer for 3D Gaussian splats: L1 + D-SSIM, Adam, schedules, densification, checkpoints.
