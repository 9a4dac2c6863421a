"""File formats: EXR images, PNG (8/16-bit), PLY meshes, DiLiGenT folders, and the exports:
PTM LRGB and HSH .rti (RTIViewer), glTF 2.0 binary (.glb)."""
