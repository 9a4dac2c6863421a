"""File formats: EXR images, PNG masks, PLY meshes, DiLiGenT folders."""
