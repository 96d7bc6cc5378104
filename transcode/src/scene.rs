//! Synthetic plenoptic inputs: the built-in demo scene and plenoptic clouds made from real meshes.
