//! Read and write COLMAP sparse models (cameras, images, points3D) in text and binary.
