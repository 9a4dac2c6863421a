"""process's "relight" output (pipeline._relight_model_stage) and the viewer's packing of it
(pipeline._viewer_model), on a rendered DiLiGenT-style folder."""
import numpy as np

from facette.pipeline import process
from facette.pipeline._relight import light_from_angles
from facette.pipeline._relight_model_stage import relight_model_stage
from facette.pipeline._viewer_model import VIEWER_PLANES, packed_model
from facette.recon import load_relight_model
from satin_scene import satin_sphere_on_a_plane


def _folder(tmp_path):
    return satin_sphere_on_a_plane(tmp_path / "objPNG")


def test_process_writes_the_model_and_it_reads_back(tmp_path):
    res = process(_folder(tmp_path), outputs=["relight"], out_dir=tmp_path / "out", method="woodham1980")
    assert (tmp_path / "out" / "relight_model.npz").is_file()
    model = res.relight_model
    back = load_relight_model(tmp_path / "out" / "relight_model.npz")
    light = light_from_angles(30.0, 20.0)
    np.testing.assert_array_equal(back.display(light), model.display(light))
    assert back.heights is not None and back.white == model.white > 0
    # the viewer's packing (8-bit maps and planes, float16 heights) keeps the picture of its
    # first 16 residual planes within ~1 level
    shipped, drawn = packed_model(model, 1, model.mask), model.first_planes(VIEWER_PLANES)
    assert model.planes.shape[-1] == 24 and shipped.planes.shape[-1] == VIEWER_PLANES
    for az, el in ((0.0, 15.0), (135.0, 45.0), (250.0, 70.0)):
        light = light_from_angles(az, el)
        diff = np.abs(shipped.display(light) - drawn.display(light))[model.mask] * 255
        assert diff.mean() < 1.0 and np.percentile(diff, 99) < 4, (az, el, diff.mean())


def test_stage_says_why_without_whole_images():
    class Res:
        relight_model = None
    notes = relight_model_stage(Res(), None, np.eye(3))
    assert Res.relight_model is None and "--memory" in notes[0]


def _on_disk(a):
    """True when `a` is a view of a memmap (a temporary file's pages, `_memory.disk_array`)."""
    while a is not None and not isinstance(a, np.memmap):
        a = a.base
    return a is not None


def test_memory_fits_the_model_from_the_bands(tmp_path, monkeypatch, force_bands):
    # --memory: the photographs never held whole, the model fitted from their spill after the
    # heights (pipeline._rti_bands keeps them), close to the untiled run's (the same normals and
    # heights; the residual's gram summed in another order)
    from test_process_memory import WHOLE, _never_whole
    from facette.pipeline import _relight_model_stage as stage
    folder = _folder(tmp_path)
    whole = process(folder, outputs=["relight"], method="rank_trimmed", **WHOLE)
    _never_whole(monkeypatch)
    force_bands(8)
    monkeypatch.setattr(stage, "MODEL_BAND_BYTES", 24 * 48 * 3 * 4 * 5)      # the model's bands: 5 rows
    banded = process(folder, outputs=["relight"], out_dir=tmp_path / "out", method="rank_trimmed", memory="1GB")
    assert banded.ps.info["tiles"] > 1 and banded.relight_model is not None
    assert (tmp_path / "out" / "relight_model.npz").is_file()
    a, b = whole.relight_model, banded.relight_model
    assert a.white == b.white and a.shininess == b.shininess and (a.heights is None) == (b.heights is None)
    for az, el in ((0.0, 15.0), (135.0, 45.0), (250.0, 70.0)):
        light = light_from_angles(az, el)
        assert np.abs(a.display(light) - b.display(light)).max() < 0.01
    # over bands the model's image-sized maps are spilled to temporary files, the file read back the same
    assert all(_on_disk(getattr(b, k)) for k in ("normals", "rho", "spec", "amb", "planes", "heights"))
    assert not _on_disk(a.rho) and not _on_disk(b.mask)
    back = load_relight_model(tmp_path / "out" / "relight_model.npz")
    np.testing.assert_array_equal(back.display(light), b.display(light))


def test_report_step_is_a_multiple_of_the_viewers():
    from facette.pipeline._relight_model_stage import report_step
    assert report_step((1424, 2144)) == 4          # the thesis camera's HDR: 536 x 356, the viewer 1072 x 712
    assert report_step((1424, 2144), side=1100) == 2
    assert report_step((40, 48)) == 1 and report_step((40, 48), side=24) == 2
    assert report_step((3000, 4000)) % 4 == 0 and -(-4000 // report_step((3000, 4000))) <= 550


def test_a_coarser_model_is_repeated_onto_the_viewers_grid(tmp_path, monkeypatch):
    # the report's model fitted at every 2nd pixel, the viewer at every pixel: its maps repeated 2 x 2,
    # the heights in the viewer's pixels, the viewer's own normals; the picture close to the full model's
    from facette.pipeline import _relight_model_stage as stage
    from facette.pipeline._viewer import viewer_data
    from facette.pipeline._viewer_model import onto_grid
    folder = _folder(tmp_path)
    full = process(folder, outputs=["relight"], method="woodham1980").relight_model
    monkeypatch.setattr(stage, "MODEL_SIDE", 24)
    res = process(folder, outputs=["normals", "height", "report"], method="woodham1980")
    coarse = res.relight_model
    assert coarse.mask.shape == (20, 24) and full.mask.shape == (40, 48)
    on = onto_grid(coarse, 1, (40, 48), res.normals)
    np.testing.assert_array_equal(on.rho[::2, ::2], coarse.rho)
    np.testing.assert_array_equal(on.rho[1::2, 1::2], coarse.rho)
    np.testing.assert_array_equal(on.heights[::2, ::2], coarse.heights * 2)
    np.testing.assert_array_equal(on.normals, res.normals.astype(np.float32))
    data, arrays = viewer_data(res.normals, res.mask, None, height=res.height, relight_model=coarse)
    assert data["width"] == 48 and data["height"] == 40 and arrays["sv_model"].mask.shape == (40, 48)
    both = full.mask & arrays["sv_model"].mask
    for az, el in ((0.0, 15.0), (135.0, 45.0), (250.0, 70.0)):
        light = light_from_angles(az, el)
        diff = np.abs(arrays["sv_model"].display(light) - full.display(light))[both] * 255
        assert np.median(diff) < 3, (az, el, np.median(diff))


def test_the_albedo_carries_the_texture_into_a_repeated_model():
    # a model fitted at every 2nd pixel of a textured surface: the viewer's albedo puts the texture back
    from facette.pipeline._viewer_model import onto_grid
    from facette.recon import RelightModel
    albedo = np.random.default_rng(3).uniform(0.2, 1.0, (5, 6, 3)).astype(np.float32)
    normals = np.broadcast_to(np.float32([0, 0, 1]), (5, 6, 3))
    coarse = RelightModel(normals[::2, ::2], np.ones((3, 3), bool), 0.5 * albedo[::2, ::2],
                          0.1 * albedo[::2, ::2], np.zeros((3, 3, 3), np.float32), 20.0)
    on = onto_grid(coarse, 1, (5, 6), normals, albedo)
    np.testing.assert_allclose(on.rho, 0.5 * albedo, rtol=1e-6)
    np.testing.assert_allclose(on.spec, 0.1 * albedo, rtol=1e-6)
    plain = onto_grid(coarse, 1, (5, 6), normals)          # without it: each pixel repeated
    np.testing.assert_array_equal(plain.rho[1::2, 1::2], coarse.rho[:2, :3])


def test_the_photographs_spill_goes_once_the_model_is_fitted():
    # over bands the photographs' spill (12 B a pixel and light) is given back before relight_model.npz is
    # written, not at the end of the run: the disk the model's file needs is not held twice
    from types import SimpleNamespace

    from facette.pipeline._relight_model_stage import ImagesSpill
    from facette.recon.synthetic import thesis_light_directions
    dirs = thesis_light_directions()
    h, w = 6, 8
    normals = np.zeros((h, w, 3), np.float32)
    normals[..., 2] = 1.0
    images = (np.clip(normals @ dirs.T, 0, None).transpose(2, 0, 1)[..., None] * [0.5, 0.4, 0.3]).astype(np.float32)
    spill = ImagesSpill(len(dirs), h, w)
    spill.add(0, images, dirs)
    res = SimpleNamespace(mask=np.ones((h, w), bool), object_mask=None, normals=normals, height=None, timings={},
                          relight_model=None)
    written = []
    relight_model_stage(res, spill, dirs, write=lambda name: written.append(spill.data))
    assert res.relight_model is not None and spill.data is None and written == [None]
