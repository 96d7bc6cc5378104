//! Read and write plenoptic point clouds (8iVSLF PLY), coloured point clouds and meshes (OBJ, glTF, PLY).
