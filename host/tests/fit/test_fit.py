import json

import numpy as np
import pytest

import facette.brdf as B
from facette.brdf import li_specular
from facette.fit import FitResult, fit_brdf, fit_genetic, fit_least_squares
from facette.fit._models import FitModel


def random_pairs(n, seed=0):
    rng = np.random.default_rng(seed)
    v = rng.normal(size=(2, n, 3))
    v[..., 2] = np.abs(v[..., 2]) + 0.05
    v /= np.linalg.norm(v, axis=-1, keepdims=True)
    return v[0], v[1]


S, O = random_pairs(250)
KD = [0.3, 0.5, 0.7]


@pytest.mark.parametrize("noise", [0.0, 0.3])
def test_least_squares_recovers_cook_torrance_with_shared_sigma_and_index(noise):
    v = B.cook_torrance1982(S, O, KD, 0.1, 1.3)
    v = v * (1 + noise * np.random.default_rng(1).normal(size=v.shape))
    r = fit_brdf(S, O, v, model="cook_torrance", select=False)
    assert r.success, r.message
    tol = 0.01 if noise == 0 else 0.08
    assert r.params["sigma"] == pytest.approx(0.1, rel=tol)
    assert r.params["n_i"] == pytest.approx(1.3, rel=tol)
    np.testing.assert_allclose(r.params["kd"], KD, rtol=tol)
    # the 1-sd uncertainties are honest: the truth lies within a few of them
    if noise:
        assert abs(r.params["sigma"] - 0.1) < 5 * r.uncertainties["sigma"]
        assert abs(r.params["n_i"] - 1.3) < 5 * r.uncertainties["n_i"]


def test_least_squares_recovers_the_li_model():
    s, o = S[:150], O[:150]
    v = B.brdf_li(s, o, KD, 0.15, 1.4, n_theta=24, n_phi=24)
    r = fit_least_squares(s, o, v, model="li", n_starts=2)
    assert r.success, r.message
    assert r.params["sigma"] == pytest.approx(0.15, rel=0.02)
    assert r.params["n_i"] == pytest.approx(1.4, rel=0.02)
    np.testing.assert_allclose(r.params["kd"], KD, rtol=0.03)


def test_genetic_algorithm_is_seeded_and_fits_cook_torrance():
    v = B.cook_torrance1982(S, O, KD, 0.1, 1.3)
    a = fit_genetic(S, O, v, model="cook_torrance", masking="vcavity", population=30, generations=40, rng=5)
    b = fit_genetic(S, O, v, model="cook_torrance", masking="vcavity", population=30, generations=40, rng=5)
    assert a.params == b.params
    assert a.success
    assert a.params["sigma"] == pytest.approx(0.1, rel=0.1)
    np.testing.assert_allclose(a.params["kd"], KD, rtol=0.1)


def test_genetic_algorithm_stops_at_the_error_threshold():
    v = B.lambert(S, O, KD)
    r = fit_genetic(S, O, v, model="lambert", population=20, generations=500, error_threshold=0.05, rng=0)
    assert r.success and r.error["weighted_rms"] < 0.05
    assert int(r.selection[-1].split()[0]) < 500


def test_selection_drops_the_interface_when_n_is_one():
    v = B.oren_nayar1994(S, O, KD, 0.3)
    r = fit_brdf(S, O, v, model="li", distribution="gaussian", masking="vcavity", interreflection=False,
                 volume_options={"n_theta": 12, "n_phi": 16}, n_starts=2)
    assert r.model in ("oren_nayar", "lambert"), r.selection
    assert any("no interface" in note for note in r.selection)
    lam = fit_brdf(S, O, B.lambert(S, O, KD), model="cook_torrance")
    assert lam.model == "lambert", lam.selection
    np.testing.assert_allclose(lam.params["kd"], KD, rtol=1e-6)


def test_no_interreflection_below_sigma_0_2():
    s, o = S[:120], O[:120]
    v = B.brdf_li(s, o, 0.6, 0.1, 1.3, masking="vcavity")
    r = fit_brdf(s, o, v, model="li", masking="vcavity", volume_options={"n_theta": 12, "n_phi": 16}, n_starts=2)
    assert r.model == "li" and not r.interreflection
    assert any("no inter-reflection term" in note for note in r.selection)


def test_to_json_has_the_brdf_json_fields_and_no_nan():
    v = B.cook_torrance1982(S, O, KD, 0.1, 1.3)
    r = fit_brdf(S, O, v, model="cook_torrance")
    d = json.loads(r.to_json())
    for key in ("model", "distribution", "masking", "parameters", "uncertainties", "fit_error", "success"):
        assert key in d
    assert d["model"] == "cook_torrance" and len(d["parameters"]["kd"]) == 3
    assert "NaN" not in r.to_json()
    np.testing.assert_allclose(r.predict(S, O), v, rtol=1e-4, atol=1e-6)


def test_failures_say_why_and_never_return_nan():
    r = fit_brdf(S[:2], O[:2], np.ones((2, 3)), model="li")
    assert not r.success and "too few" in r.message
    assert json.loads(r.to_json())["parameters"] == {}
    z = fit_brdf(S, O, np.zeros((len(S), 3)), model="cook_torrance")
    assert not z.success and "zero" in z.message
    v = B.lambert(S, O, KD)
    v[:10] = np.nan
    r = fit_brdf(S, O, v, model="lambert")
    assert r.success and "10 of 250 samples dropped" in r.message


def test_bad_input_raises_clear_errors():
    with pytest.raises(ValueError, match=r"\(N, 3\)"):
        fit_brdf(S[:, :2], O, np.ones(len(S)))
    with pytest.raises(ValueError, match="one row per"):
        fit_brdf(S, O, np.ones(len(S) + 1))
    with pytest.raises(ValueError, match="method"):
        fit_brdf(S, O, np.ones(len(S)), method="annealing")
    with pytest.raises(ValueError, match="weighting"):
        fit_brdf(S, O, np.ones(len(S)), weighting="log")
    with pytest.raises(ValueError, match="V-cavities"):
        fit_brdf(S, O, np.ones(len(S)), interreflection=True, masking="smith")


def test_counts_weight_the_cells():
    v = B.lambert(S, O, 0.5)[:, None] * np.ones((1, 1))
    v[0] = 5.0  # one outlier cell holding a single sample, the others 1000
    counts = np.full(len(S), 1000)
    counts[0] = 1
    r = fit_brdf(S, O, v, model="lambert", counts=counts, weighting="absolute")
    assert r.params["kd"][0] == pytest.approx(0.5, rel=0.02)
    assert isinstance(r, FitResult)


def test_cell_averaged_values_are_fitted_without_bias_with_o_spread():
    # values that average a narrow lobe over 4° cells: fitting them at the cell centres widens σ,
    # the forward model (model averaged over the cell) does not
    rng = np.random.default_rng(4)
    n, k = 300, 9
    s = np.broadcast_to([np.sin(0.6), 0, np.cos(0.6)], (n, 3))
    th = rng.uniform(0.3, 0.9, n)
    ph = rng.uniform(-0.4, 0.4, n) + np.pi
    half = np.radians(2.0)
    dt, dp = np.meshgrid(np.linspace(-half, half, 3), np.linspace(-half, half, 3), indexing="ij")
    tt = th[:, None] + dt.ravel()[None, :]
    pp = ph[:, None] + dp.ravel()[None, :] / np.sin(th)[:, None]
    spread = np.stack([np.sin(tt) * np.cos(pp), np.sin(tt) * np.sin(pp), np.cos(tt)], axis=-1)
    centres = np.stack([np.sin(th) * np.cos(ph), np.sin(th) * np.sin(ph), np.cos(th)], axis=-1)
    vals = B.cook_torrance1982(s[:, None, :], spread, 0.5, 0.05, 1.3).mean(axis=1)
    plain = fit_brdf(s, centres, vals, model="cook_torrance", select=False)
    fwd = fit_brdf(s, centres, vals, model="cook_torrance", select=False, o_spread=spread)
    assert fwd.params["sigma"] == pytest.approx(0.05, rel=0.01)
    assert abs(plain.params["sigma"] - 0.05) > 5 * abs(fwd.params["sigma"] - 0.05)
    with pytest.raises(ValueError, match="o_spread"):
        fit_brdf(s, centres, vals, model="cook_torrance", o_spread=spread[:, :, :2])


def test_projected_kd_is_the_closed_form_optimum():
    from facette.fit import FitModel
    from facette.fit._fit import prepare_samples
    v = B.brdf_li(S, O, KD, 0.15, 1.4, n_theta=16, n_phi=24)
    data = prepare_samples(S, O, v, weighting="absolute")
    fm = FitModel("li", data.s, data.o, 3, volume_options={"n_theta": 16, "n_phi": 24})
    p = fm.project_kd([0.15, 1.4, 0.9, 0.1, 0.2], data.values, data.weights)
    np.testing.assert_allclose(p[2:], KD, rtol=1e-9)
    ct = FitModel("cook_torrance", data.s, data.o, 3, masking="vcavity")
    vc = B.cook_torrance1982(S, O, KD, 0.1, 1.3)
    np.testing.assert_allclose(ct.project_kd([0.1, 1.3, 0, 0, 0], vc, np.ones_like(vc))[2:], KD, rtol=1e-9)


def test_genetic_algorithm_with_projection_recovers_li():
    s, o = S[:120], O[:120]
    v = B.brdf_li(s, o, KD, 0.15, 1.4, n_theta=12, n_phi=16)
    r = fit_genetic(s, o, v, model="li", population=24, generations=20, project_kd=True, rng=3,
                    volume_options={"n_theta": 12, "n_phi": 16})
    assert r.params["sigma"] == pytest.approx(0.15, rel=0.05)
    assert r.params["n_i"] == pytest.approx(1.4, rel=0.05)
    np.testing.assert_allclose(r.params["kd"], KD, rtol=0.05)


def test_interreflection_term_is_kept_when_the_data_needs_it():
    s, o = S[:120], O[:120]
    v = B.brdf_li(s, o, [0.4, 0.8], 0.4, 1.4, "beckmann", "vcavity", n_theta=24, n_phi=24)  # σ ≥ 0.2: with IR
    r = fit_brdf(s, o, v, model="li", masking="vcavity", n_starts=2, volume_options={"n_theta": 16, "n_phi": 24})
    assert r.interreflection, r.selection
    assert any("inter-reflection term kept" in note for note in r.selection)
    assert r.params["sigma"] == pytest.approx(0.4, rel=0.02)
    np.testing.assert_allclose(r.params["kd"], [0.4, 0.8], rtol=0.02)
    assert json.loads(r.to_json())["interreflection"] is True


def test_the_brdf_fits_model_evaluates_the_lobe_on_directions_normalised_once():
    """FitModel keeps the cell directions unit and broadcast (s (N, 1, 3) against o (N, K, 3)):
    its lobe equals li_specular on the raw, unnormalised directions."""
    rng = np.random.default_rng(5)
    s = np.abs(rng.normal(size=(50, 3))) * 3.0                 # not unit: the model normalises
    o_spread = np.abs(rng.normal(size=(50, 4, 3))) * 0.5
    m = FitModel("li", s, s, 3, o_spread=o_spread)
    want = li_specular(s[:, None, :], o_spread, 0.2, 1.4).mean(axis=1)
    np.testing.assert_allclose(m._parts(0.2, 1.4)["spec"], want, rtol=1e-12)


def test_the_fit_models_cache_gives_the_same_values_from_two_threads():
    # fit_least_squares runs its starts on two threads that share one FitModel and its cache
    # (cleared past 64 entries): every prediction must be the one a lone thread gets
    from concurrent.futures import ThreadPoolExecutor
    fm = FitModel("li", S[:60], O[:60], 3, volume="approx")
    params = [np.array([0.05 + 0.004 * k, 1.2 + 0.003 * k, 0.3, 0.5, 0.7]) for k in range(150)]
    alone = [FitModel("li", S[:60], O[:60], 3, volume="approx").predict(p) for p in params]
    with ThreadPoolExecutor(2) as pool:
        both = list(pool.map(fm.predict, params + params[::-1]))
    for got, want in zip(both, alone + alone[::-1]):
        np.testing.assert_array_equal(got, want)
    assert 150 <= fm.n_evaluations <= 300
