"""`process`'s cast-shadow step (pipeline._shadows): the lights the surface hides from itself are
no samples, alternated with the normals."""
import numpy as np
import pytest

from facette.errors import BadInputError
from facette.io.diligent import write_diligent
from facette.pipeline import ProcessOptions, process
from facette.recon.synthetic import angular_error_deg

from shadow_scenes import groove_scene


def _folder(path, d):
    top = 60000.0 / float(d["images"].max())
    write_diligent(path, np.round(d["images"] * top).astype(np.uint16), d["light_dirs"],
                   np.full((len(d["images"]), 3), top / 65535.0), d["mask"])
    return path


@pytest.fixture(scope="module")
def groove(tmp_path_factory):
    """The analytic groove, its hidden lights still at 40 % of their direct light (the walls' light)."""
    d = groove_scene("groove", fill=0.4)
    return d, _folder(tmp_path_factory.mktemp("groove") / "groove", d)


def test_hidden_lights_are_no_samples(groove):
    d, folder = groove
    run = lambda s: process(folder, outputs=["normals"], method="woodham1980", shadows=s, interreflections=False)
    off, on = run("off"), run("on")
    hid = d["hidden"].any(0)                    # the pixels some light is hidden from
    err = lambda r: angular_error_deg(r.normals, d["normals"])[hid].mean()
    assert err(off) > 2.0                        # least squares takes the shadowed values as samples
    assert err(on) < 0.3 * err(off), (err(on), err(off))
    assert on.quality["shadows"]["applied"] and on.quality["shadows"]["hidden_share"][-1] > 0.01
    assert any(n.startswith("shadows: the surface's own heights hide") for n in on.notes)
    assert off.quality.get("shadows") is None
    # the hidden lights join the shadow map the reflectance samples leave out
    assert on.ps.shadow[hid].any()


def test_the_default_method_gains_on_the_groove_and_a_convex_object_is_left_as_it_was(tmp_path, groove):
    d, folder = groove
    hid = d["hidden"].any(0)
    res = process(folder, outputs=["normals"], interreflections=False)
    off = process(folder, outputs=["normals"], interreflections=False, shadows="off")
    err = lambda r: angular_error_deg(r.normals, d["normals"])[hid].mean()
    assert res.quality["shadows"]["applied"] and err(res) <= err(off) + 0.05, (err(res), err(off))
    # a dome hides nothing: "auto" says so and the images are used as they are
    y, x = np.mgrid[:48, :48] - 23.5
    z = np.sqrt(np.clip(30.0 ** 2 - x * x - y * y, 1, None))
    n = np.dstack([x, -y, z]) / np.linalg.norm(np.dstack([x, -y, z]), axis=-1, keepdims=True)
    im = 0.6 * np.clip(np.einsum("md,hwd->mhw", d["light_dirs"], n), 0, None)
    dome = _folder(tmp_path / "dome", {"images": im.astype(np.float32), "light_dirs": d["light_dirs"],
                                       "mask": np.ones((48, 48), bool)})
    auto = process(dome, outputs=["normals"], method="woodham1980", interreflections=False)
    plain = process(dome, outputs=["normals"], method="woodham1980", interreflections=False, shadows="off")
    assert auto.quality["shadows"]["applied"] is False and any("too few to matter" in n for n in auto.notes)
    np.testing.assert_array_equal(auto.normals, plain.normals)


def test_the_option_is_checked():
    with pytest.raises(BadInputError, match="shadows must be one of"):
        ProcessOptions(shadows="maybe")


TIMES = ("cpu_seconds", "seconds_before_solve", "cpu_seconds_before_solve")


@pytest.mark.parametrize("method, bins", [("rank_trimmed", None), ("li_alternating", (1000, 2304)),
                                          ("woodham1980", (1000, 2304))])
def test_over_bands_the_step_gives_the_whole_run_s_normals(groove, monkeypatch, method, bins, force_bands):
    # bands of 5 rows (--memory): the images binned band by band on the whole image's bins, the alternation
    # on them, each band's solve without its rows of the hidden lights. bins: the decision's 4 x 4 and the
    # alternation's 2 x 2 (the shadow pass then reads bands of 4 rows, the solve's of 5 start inside bins)
    import facette.pipeline._shadows as shadows
    d, folder = groove
    if bins:
        monkeypatch.setattr(shadows, "SHADOW_PIXELS", bins[0])
        monkeypatch.setattr(shadows, "HORIZON_PIXELS", bins[1])
    options = dict(outputs=["normals", "albedo"], method=method, interreflections=False, shadows="on",
                   ps_options={"coarse_pixels": 400} if method == "li_alternating" else {})
    whole = process(folder, **options)
    force_bands(5)
    bands = process(folder, **options, memory="1GB")
    assert bands.ps.info["tiles"] > 1 and bands.ps.info["rows_per_tile"] == 5
    q, qb = whole.quality["shadows"], bands.quality["shadows"]
    assert q["applied"] and q["hidden_share"][-1] > 0.01 and q["bin"] == (4 if bins else 1)
    assert {k: v for k, v in q.items() if k not in TIMES} == {k: v for k, v in qb.items() if k not in TIMES}
    hid = d["hidden"].any(0)
    off = process(folder, **dict(options, shadows="off"), memory="1GB")       # and the step did change them
    if method == "woodham1980":      # a band with no value missing is solved by the pseudo-inverse, the
        assert _angle(bands.normals, whole.normals).max() < 0.1    # whole image by the normal equations
        assert _angle(off.normals, whole.normals)[hid].mean() > 1.0
    else:                             # the robust methods trim most shadows themselves: less to change
        np.testing.assert_array_equal(bands.normals, whole.normals)
        np.testing.assert_array_equal(bands.albedo, whole.albedo)
        assert (_angle(off.normals, whole.normals)[hid] > 0.01).sum() > 20


def _angle(a, b):
    return np.degrees(np.arccos(np.clip(np.sum(a * b, axis=-1), -1, 1)))


def test_auto_decides_on_binned_images_and_solves_at_full_size(groove, monkeypatch):
    # "auto" reads the hidden share on images binned to SHADOW_PIXELS object pixels (here 3 x 3):
    # the groove still hides enough, and the alternation then runs at full size, so the normals are
    # those of the unbinned decision
    import facette.pipeline._shadows as shadows
    d, folder = groove
    full = process(folder, outputs=["normals"], method="woodham1980", interreflections=False)
    monkeypatch.setattr(shadows, "SHADOW_PIXELS", 1000)
    coarse = process(folder, outputs=["normals"], method="woodham1980", interreflections=False)
    q = coarse.quality["shadows"]
    assert q["bin"] == 4 and full.quality["shadows"]["bin"] == 1 and q["applied"]
    assert abs(q["decided_on"] - full.quality["shadows"]["decided_on"]) < 0.5 * full.quality["shadows"]["decided_on"]
    np.testing.assert_array_equal(coarse.normals, full.normals)


def test_the_alternation_runs_at_the_horizon_test_s_bin_and_keeps_its_gain(groove, monkeypatch):
    # at most HORIZON_PIXELS cells for the horizon test's heights: the robust passes solve the images
    # binned as much (here 2 x 2), the hidden lights are those bins', the method solves every pixel.
    # Heights binned 2 x 2 round the groove's rims off (0.02 -> 0.92 deg with woodham1980, the same
    # when the robust passes ran at full size): still well under the shadows left in
    import facette.pipeline._shadows as shadows
    d, folder = groove
    hid = d["hidden"].any(0)
    run = lambda s: process(folder, outputs=["normals"], method="woodham1980", shadows=s, interreflections=False)
    full, off = run("on"), run("off")
    monkeypatch.setattr(shadows, "HORIZON_PIXELS", d["mask"].sum() // 4)
    coarse = run("on")
    q = coarse.quality["shadows"]
    assert q["alternation_bin"] == 2 and full.quality["shadows"]["alternation_bin"] == 1 and q["applied"]
    err = lambda r: angular_error_deg(r.normals, d["normals"])[hid].mean()
    assert err(coarse) < 0.5 * err(off), (err(coarse), err(full), err(off))
    # found per bin, taken out at every pixel of it: the shadow map holds whole bins
    assert coarse.normals.shape == full.normals.shape and coarse.ps.shadow[hid].any()


def test_hidden_lights_of_bins_cover_every_pixel_of_the_mask():
    from facette.pipeline._shadows import upsampled
    hidden = np.zeros((2, 2, 3), bool)
    hidden[0, 1, 2] = True
    hidden[1, 0, 0] = True
    mask = np.ones((5, 7), bool)              # 5 x 7 by bins of 2: the last row and column take the nearest bin's
    mask[0, 0] = False
    up = upsampled(hidden, 2, mask)
    assert up.shape == (2, 5, 7)
    assert up[0, 2:, 4:].all() and up[0].sum() == 9
    assert not up[1, 0, 0] and up[1, :2, :2].sum() == 3 and up[1].sum() == 3
    np.testing.assert_array_equal(upsampled(hidden, 1, np.ones((2, 3), bool)), hidden)


def test_hidden_lights_of_bins_at_every_pixel_as_numpy_indexes_them():
    """The compiled spread (`upsampled`) against numpy's indexing of the bins, whole and for a band of rows."""
    from facette.pipeline._shadows import upsampled
    rng = np.random.default_rng(3)
    hidden = rng.random((3, 6, 8)) < 0.3
    mask = rng.random((20, 25)) < 0.8
    for f, r0, rows in ((3, 0, 20), (3, 6, 9), (2, 4, 16)):
        part = mask[r0:r0 + rows]
        r = np.minimum(np.arange(r0, r0 + len(part)) // f, hidden.shape[1] - 1)
        c = np.minimum(np.arange(part.shape[1]) // f, hidden.shape[2] - 1)
        np.testing.assert_array_equal(upsampled(hidden, f, part, r0), hidden[:, r[:, None], c[None, :]] & part[None])


def test_binned_images_keep_what_is_missing_out():
    from facette.pipeline._shadows import binned
    im = np.arange(2 * 4 * 6, dtype=np.float32).reshape(2, 4, 6)
    im[0, 0, 0] = np.nan
    im[1, :2, :2] = np.nan                     # a block missing whole under light 1
    mask = np.ones((4, 6), bool)
    mask[3, 5] = False
    out, dirs, m = binned(im, np.eye(3)[:2], mask, 2)
    assert out.shape == (2, 2, 3) and m.tolist() == [[True, True, True], [True, True, False]]
    assert out[0, 0, 0] == pytest.approx(np.mean([1, 6, 7])) and np.isnan(out[1, 0, 0])
    assert out[1, 1, 2] == pytest.approx(np.mean(im[1, 2:4, 4:6]))
    assert binned(im, np.eye(3)[:2], mask, 1)[0] is im


@pytest.mark.parametrize("layout", ["rgb", "grey", "channel view", "float64"])
def test_hidden_values_are_taken_out_of_a_copy_as_numpy_would(layout):
    from facette.pipeline._shadows import _without
    rng = np.random.default_rng(3)
    rgb = rng.random((3, 5, 7, 4)).astype(np.float32)
    images = {"rgb": rgb, "grey": np.ascontiguousarray(rgb[..., 1]), "channel view": rgb[..., 1],
              "float64": rgb.astype(np.float64)}[layout]
    given = images.copy()
    hidden = rng.random((3, 5, 7)) < 0.3
    for method, fill in (("rank_trimmed", 0.0), ("woodham1980", np.nan)):
        want = np.array(images, np.float32)
        want[hidden] = fill                      # every channel of a hidden value
        got = _without(images, hidden, method)
        assert got.dtype == np.float32 and got.shape == images.shape
        np.testing.assert_array_equal(got, want)
        np.testing.assert_array_equal(images, given)       # the images themselves untouched
