"""The relighting model on rendered scenes: held-out lights, raking lights, its file."""
import numpy as np
import pytest

from facette.errors import BadInputError
from facette.recon import fit_hsh, hsh_basis, integrate, srgb_encode
from facette.recon import fit_relight_model
from facette.recon._relight_model import (_kernel, _kernel_choice, _loo_error, cast_shadow, load_relight_model,
                                          save_relight_model)
from facette.recon.synthetic import render, sphere_on_plane


def _dome(n_rings=(8, 12, 16), elevations=(70.0, 45.0, 25.0)):
    dirs = []
    for k, el in zip(n_rings, elevations):
        for j in range(k):
            az, e = np.radians(360.0 * j / k + 11 * k), np.radians(el)
            dirs.append([np.cos(e) * np.cos(az), np.cos(e) * np.sin(az), np.sin(e)])
    return np.array(dirs)


@pytest.fixture(scope="module")
def scene():
    sc = sphere_on_plane(64, 64)
    dirs = _dome()
    lin = render(sc, dirs, material="satin", albedo=(0.7, 0.5, 0.3)).astype(np.float32)
    lin /= np.percentile(lin, 99.5)
    held = np.arange(5, len(dirs), 6)
    train = np.setdiff1d(np.arange(len(dirs)), held)
    return sc, dirs, lin, train, held


def _psnr(pred, truth):
    p8, t8 = np.round(np.clip(pred, 0, 1) * 255), np.round(np.clip(truth, 0, 1) * 255)
    return 10 * np.log10(255 ** 2 / max(np.mean((p8 - t8) ** 2), 1e-9))


def _fit(sc, dirs, lin, train, shadows=True):
    heights = integrate(sc.normals, mask=sc.mask) if shadows else None
    return fit_relight_model(lin[train], dirs[train], sc.mask, sc.normals, heights=heights)


def test_beats_hsh3_at_held_out_lights(scene):
    sc, dirs, lin, train, held = scene
    model = _fit(sc, dirs, lin, train)
    hsh = fit_hsh(lin[train], dirs[train], 3, white=1.0, encoding="srgb")
    shown = srgb_encode(np.clip(lin, 0, 1))
    ours = np.mean([_psnr(model.display(dirs[h]), shown[h]) for h in held])
    theirs = np.mean([_psnr(hsh.coeffs @ hsh_basis(dirs[h], 3), shown[h]) for h in held])
    assert ours > theirs + 2.0, (ours, theirs)


def test_never_negative_at_raking_light(scene):
    sc, dirs, lin, train, _ = scene
    model = _fit(sc, dirs, lin, train)
    for az in np.radians(np.arange(0, 360, 45)):
        t = np.radians(75.0)
        light = np.array([np.sin(t) * np.cos(az), np.sin(t) * np.sin(az), np.cos(t)])
        assert model.display_raw(light).min() >= 0.0
        assert model.physical(light).min() >= 0.0


def test_cast_shadow_falls_behind_the_bump():
    sc = sphere_on_plane(64, 64)
    h = sc.height                    # pixels: the hemisphere's radius is in pixels
    light = np.array([np.cos(np.radians(20)), 0.0, np.sin(np.radians(20))])   # low, from +x
    vis = cast_shadow(h, light)
    row = 32
    assert vis[row, 2] < 0.5        # left of the sphere, away from the light: shadowed
    assert vis[row, 61] > 0.99      # the lit side
    assert vis[2, 2] > 0.99         # a corner the sphere does not shade


def test_round_trips_through_its_file(scene, tmp_path):
    sc, dirs, lin, train, held = scene
    model = _fit(sc, dirs, lin, train)
    save_relight_model(tmp_path / "m.npz", model)
    back = load_relight_model(tmp_path / "m.npz")
    for h in held[:3]:
        np.testing.assert_array_equal(back.display(dirs[h]), model.display(dirs[h]))
    (tmp_path / "other.npz").write_bytes(b"not a model")
    with pytest.raises(BadInputError):
        load_relight_model(tmp_path / "other.npz")


def test_leave_one_light_out_error_is_the_refitted_one():
    # the closed form the residual's kernel is chosen by equals refitting without each light
    rng = np.random.default_rng(1)
    dirs = _dome((5, 7), (60.0, 30.0))
    rows = rng.normal(size=(9, len(dirs)))
    kern = _kernel(dirs, dirs, 3.0, 0.1)
    brute = 0.0
    for i in range(len(dirs)):
        keep = np.setdiff1d(np.arange(len(dirs)), [i])
        wts = np.linalg.solve(kern[np.ix_(keep, keep)] + 0.05 * np.eye(len(keep)), rows[:, keep].T)
        brute += np.sum((kern[i, keep] @ wts - rows[:, i]) ** 2)
    assert np.isclose(_loo_error(kern, 0.05, rows.T @ rows), brute, rtol=1e-9)


def test_residual_of_noise_alone_is_not_kept(scene):
    # a residual no light predicts (independent noise per light) is left out: physics alone
    sc, dirs, lin, train, _ = scene
    rng = np.random.default_rng(2)
    rows = rng.normal(size=(500, len(train)))
    assert _kernel_choice(rows.T @ rows, dirs[train], 0.2)[0] is None


def test_auto_keeps_cast_shadows_where_they_predict_better(scene):
    # the rendered sphere casts shadows on its plane: the model with them predicts the fitted
    # lights left out better, and "auto" keeps it
    sc, dirs, lin, train, _ = scene
    heights = integrate(sc.normals, mask=sc.mask)
    auto = fit_relight_model(lin[train], dirs[train], sc.mask, sc.normals, heights=heights)
    flat = fit_relight_model(lin[train], dirs[train], sc.mask, sc.normals)
    assert auto.heights is not None and auto.loo_error < flat.loo_error


def test_compiled_normal_equations_are_numpys_bit_for_bit():
    # the compiled sums are numpy's float32 products summed light after light in float64: the same
    # bits (signed zeros too: a pixel all of whose products are -0.0), so the model's maps do not move
    from facette.recon._relight_model import _normal_equations
    rng = np.random.default_rng(3)
    m, n = 12, 5000
    basis = rng.normal(size=(m, n, 3)).astype(np.float32)
    basis[:, :7, 1] = 0.0
    basis[:, :7, 0] = -1.0
    values = rng.normal(size=(m, n, 3)).astype(np.float32) * np.float32(1e3)
    weights = rng.random((m, n)).astype(np.float32)
    weights[:, 3] = 0.0
    fast, slow = _normal_equations(basis, values, weights), _normal_equations(basis, values, weights, compiled=False)
    for a, b in zip(fast, slow):
        assert a.shape == b.shape and np.array_equal(a.view(np.uint64), b.view(np.uint64))
