"""facette.methods: the one table of photometric-stereo methods, its options and its dispatcher."""
import subprocess
import sys

import numpy as np
import pytest

import facette.recon
from facette.fit import ps_li_alternating
from facette.methods import (ALL_OPTIONS, METHOD_OPTIONS, PS_DEFAULT, PS_METHODS, options_for,
                             photometric_stereo)
from facette.recon import ps_hierarchical_tautzia2016, ps_rank_trimmed, ps_woodham1980
from facette.recon.synthetic import render, sphere_on_plane, thesis_light_directions

EVERY_METHOD = ["woodham1980", "hierarchical_tautzia2016", "rpca_wu2010", "rank_trimmed", "bipolynomial_shi2014",
                "bivariate_ikehata2014", "consensus_higo2010", "li_alternating"]
THRESHOLDS = {"t_ombre": 1.2, "t_spec": 0.3, "t_source": 8.0, "t_residual": 0.05}


def test_importing_the_table_module_alone_gives_every_method():
    # a fresh interpreter: nothing else of facette imported first (li_alternating used to
    # appear only once facette.fit had been imported)
    code = "import facette.methods as m; print(','.join(m.PS_METHODS))"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip().split(",") == EVERY_METHOD
    assert list(PS_METHODS) == EVERY_METHOD and PS_DEFAULT in PS_METHODS
    assert PS_METHODS["brdf_li"] is ps_li_alternating and PS_METHODS["HIERARCHICAL"] is ps_hierarchical_tautzia2016
    # one place: the layer below has no table of its own
    assert not hasattr(facette.recon, "PS_METHODS") and not hasattr(facette.recon, "photometric_stereo")


def test_the_table_cannot_be_added_to():
    with pytest.raises(TypeError, match="fixed"):
        PS_METHODS.add("mine", ps_woodham1980)
    with pytest.raises(TypeError):
        METHOD_OPTIONS["mine"] = frozenset()
    assert list(PS_METHODS) == EVERY_METHOD


def test_each_method_declares_its_options_by_its_signature():
    assert METHOD_OPTIONS["woodham1980"] == {"mask", "channel", "saturation"}
    assert set(THRESHOLDS) <= METHOD_OPTIONS["hierarchical_tautzia2016"]
    assert {"trim", "rounds"} <= METHOD_OPTIONS["rank_trimmed"]
    assert {"init", "init_options", "rounds", "materials", "t_residual"} <= METHOD_OPTIONS["li_alternating"]
    assert ALL_OPTIONS == frozenset().union(*METHOD_OPTIONS.values())


def test_one_bag_of_options_each_method_takes_its_own():
    bag = {**THRESHOLDS, "mask": "m", "trim": 0.2, "materials": "auto"}
    assert options_for("least_squares", bag) == {"mask": "m"}
    assert options_for("hierarchical", bag) == {**THRESHOLDS, "mask": "m"}
    assert options_for("rank_trimmed", bag) == {"mask": "m", "trim": 0.2}
    assert options_for("rpca_wu2010", bag, mask=None) == {"mask": None}          # keywords win
    with pytest.raises(ValueError, match="unknown photometric-stereo option.*t_ombr\\b"):
        options_for("woodham1980", {"t_ombr": 1.0})                            # no method takes it
    with pytest.raises(ValueError, match="unknown photometric-stereo method 'magic'"):
        options_for("magic", {})


def test_li_alternating_starts_from_a_method_named_in_the_table():
    # the hierarchy as start: it takes its thresholds from the same bag (t_residual means the
    # same to both); li's `rounds` are not rank_trimmed's
    kw = options_for("li_alternating", {**THRESHOLDS, "init": "hierarchical", "rounds": 2, "mask": "m"})
    assert kw["init"] is ps_hierarchical_tautzia2016
    assert kw["init_options"] == THRESHOLDS and kw["rounds"] == 2 and kw["t_residual"] == 0.05
    kw = options_for("li_alternating", {**THRESHOLDS, "rounds": 2})             # default start
    assert "init" not in kw and kw["init_options"] is None and kw["rounds"] == 2
    kw = options_for("li_alternating", {"init": ps_rank_trimmed, "trim": 0.25, "rounds": 3})
    assert kw["init"] is ps_rank_trimmed and kw["init_options"] == {"trim": 0.25}
    given = {"t_ombre": 1.0}
    kw = options_for("li_alternating", {**THRESHOLDS, "init": "hierarchical", "init_options": given})
    assert kw["init_options"] is given                                        # given: kept as is
    with pytest.raises(ValueError, match="unknown photometric-stereo method 'nope'"):
        options_for("li_alternating", {"init": "nope"})
    L = thesis_light_directions()[:6]
    with pytest.raises(ValueError, match="another method"):
        photometric_stereo(np.ones((6, 4, 4)), L, method="li_alternating", init="li_alternating")
    with pytest.raises(TypeError, match="by name: facette.methods"):      # the function itself takes no name
        ps_li_alternating(np.ones((6, 4, 4)), L, init="hierarchical")


def test_dispatch_gives_the_functions_result():
    L = thesis_light_directions()
    sc = sphere_on_plane(24, 24)
    imgs, mask = render(sc, L, "glossy"), sc.sphere
    by_name = photometric_stereo(imgs, L, method="least_squares", options={**THRESHOLDS, "trim": 0.2})
    direct = ps_woodham1980(imgs, L)
    assert by_name.method == "woodham1980"
    np.testing.assert_array_equal(by_name.normal, direct.normal)
    by_name = photometric_stereo(imgs, L, method="hierarchical", options=THRESHOLDS, mask=mask)
    direct = ps_hierarchical_tautzia2016(imgs, L, mask=mask, **THRESHOLDS)
    np.testing.assert_array_equal(by_name.normal, direct.normal)
