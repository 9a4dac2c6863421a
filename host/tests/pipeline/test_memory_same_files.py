"""`process` on one folder with and without `--memory` writes the same files (issue 49 item 2):
the default method, the normals filled where no light reached (`_filled`), the heights, the mask;
the band loop forced to bands of a few rows."""
import numpy as np
import pytest

from facette.io.diligent import write_diligent
from facette.pipeline import process
from facette.recon.synthetic import render, sphere_on_plane, thesis_light_directions

L = thesis_light_directions()
OUTPUTS = ["normals", "albedo", "mask", "height"]
FILES = ("normal.exr", "albedo.exr", "mask.png", "height.exr")
# li_alternating's model over bands needs more valid pixels than its coarse pass's limit: lowered
LI = {"ps_options": {"coarse_pixels": 400}}


@pytest.fixture(scope="module")
def folder(tmp_path_factory):
    """A glossy sphere on a plane, 40x48 px, 16-bit PNGs, with a 3x4 patch of the plane black in every
    photograph (inside the mask: no light above the noise, its normals filled)."""
    scene = sphere_on_plane(40, 48, border=2)
    images = render(scene, L, material="glossy", noise=0.002, rng=np.random.default_rng(7))
    images[:, 3:6, 40:44] = 0.0
    raw = np.clip(np.rint(images * 3.0 * 65535), 0, 65535).astype(np.uint16)
    path = tmp_path_factory.mktemp("same") / "dil"
    write_diligent(path, raw, L, np.full((len(L), 3), 3.0), scene.mask)
    return path


def test_process_with_and_without_memory_writes_the_same_bytes(folder, tmp_path, monkeypatch, force_bands):
    whole = process(folder, outputs=OUTPUTS, out_dir=tmp_path / "whole", **LI)
    force_bands(5)
    banded = process(folder, outputs=OUTPUTS, out_dir=tmp_path / "banded", memory="1GB", **LI)
    assert banded.ps.info["tiles"] > 1 and banded.ps.method == whole.ps.method == "li_alternating"
    for res in (whole, banded):           # the gap was filled in both (over bands: from the map on disk)
        assert res.filled is not None and res.filled[3:6, 40:44].all()
    assert isinstance(banded.normals, np.memmap)       # filled into a map on disk, a piece of rows at a time
    differ = {name: np.count_nonzero(np.frombuffer((tmp_path / "whole" / name).read_bytes(), np.uint8) !=
                                     np.frombuffer((tmp_path / "banded" / name).read_bytes(), np.uint8))
              if (tmp_path / "whole" / name).stat().st_size == (tmp_path / "banded" / name).stat().st_size else "size"
              for name in FILES}
    assert all(v == 0 for v in differ.values()), differ
