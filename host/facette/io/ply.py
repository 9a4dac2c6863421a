"""PLY triangle meshes (binary little-endian or ASCII), readable by MeshLab, Blender, Open3D."""
from pathlib import Path

import numpy as np

from facette.io.atomic import atomic_path

__all__ = ["write_ply", "read_ply"]


def write_ply(path, vertices, faces, binary=True, comment="facette"):
    """Write vertices (V, 3) float (mm) and faces (F, 3) integer indices as PLY.

    binary : little-endian binary (compact) or ASCII (readable). Indices must be in [0, V).
    """
    v = np.asarray(vertices, dtype="<f4")
    f = np.asarray(faces)
    if v.ndim != 2 or v.shape[1] != 3:
        raise ValueError(f"vertices must have shape (V, 3), got {v.shape}")
    if f.ndim != 2 or f.shape[1] != 3:
        raise ValueError(f"faces must have shape (F, 3), got {f.shape}")
    if f.size and (f.min() < 0 or f.max() >= len(v)):
        raise ValueError(f"face indices must be in [0, {len(v)}), found {f.min()}..{f.max()}")
    fmt = "binary_little_endian" if binary else "ascii"
    header = (f"ply\nformat {fmt} 1.0\ncomment {comment}\nelement vertex {len(v)}\n"
              "property float x\nproperty float y\nproperty float z\n"
              f"element face {len(f)}\nproperty list uchar int vertex_indices\nend_header\n")
    with atomic_path(path, needed=len(header) + v.nbytes + 13 * len(f)) as tmp, open(tmp, "wb") as out:
        out.write(header.encode("ascii"))
        if binary:
            out.write(v.tobytes())
            rec = np.zeros(len(f), dtype=[("n", "u1"), ("i", "<i4", (3,))])
            rec["n"] = 3
            rec["i"] = f
            out.write(rec.tobytes())
        else:
            np.savetxt(out, v, fmt="%.6g")
            np.savetxt(out, np.c_[np.full(len(f), 3), f], fmt="%d")


def read_ply(path):
    """Read a triangle PLY written by `write_ply`. Returns (vertices (V, 3) float32, faces (F, 3) int32)."""
    data = Path(path).read_bytes()
    end = data.index(b"end_header\n") + len(b"end_header\n")
    header = data[:end].decode("ascii").splitlines()
    nv = int(next(l for l in header if l.startswith("element vertex")).split()[-1])
    nf = int(next(l for l in header if l.startswith("element face")).split()[-1])
    if "format ascii 1.0" in header:
        rows = data[end:].decode("ascii").split("\n")
        v = np.array([r.split() for r in rows[:nv]], dtype=np.float32).reshape(nv, 3)
        f = np.array([r.split()[1:4] for r in rows[nv:nv + nf]], dtype=np.int32).reshape(nf, 3)
        return v, f
    v = np.frombuffer(data, "<f4", nv * 3, end).reshape(nv, 3)
    rec = np.frombuffer(data, [("n", "u1"), ("i", "<i4", (3,))], nf, end + nv * 12)
    return v.astype(np.float32), rec["i"].astype(np.int32)
