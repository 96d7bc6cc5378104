//! Reference renderer: plenoptic clouds and meshes to RGB, alpha and depth images per camera.
