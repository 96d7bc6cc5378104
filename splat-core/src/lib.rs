//! 3D Gaussian splats: spherical harmonics, EWA projection, tile rasteriser with exact gradients, 3DGS PLY.
