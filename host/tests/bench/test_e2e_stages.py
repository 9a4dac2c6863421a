"""bench e2e --stages / --viewer on a small generated scan: every stage's CPU counted once, the
viewer's picture scored against the photographs."""
import numpy as np

import facette.pipeline._process as proc
import facette.pipeline._tiled_process as whole     # the band loop: its one band's solve
from facette.bench._e2e_stages import WITHIN, stage_table
from facette.bench._e2e_viewer import viewer_rows
from facette.bench._sim_scan import write_scan
from facette.recon.synthetic import render, sphere_on_plane, thesis_light_directions


def _scan(tmp_path):
    sc = sphere_on_plane(32, 40)
    return write_scan(tmp_path / "scan", sc, render(sc, thesis_light_directions(), "satin", noise=0.002))


def test_stage_table_counts_each_stage_once_and_puts_things_back(tmp_path):
    pool, solve = proc.ThreadPoolExecutor, whole.photometric_stereo
    table = stage_table(_scan(tmp_path), outputs=["normals", "height", "mesh", "rti", "report"],
                        method="woodham1980")
    assert {"load", "uncertainty", "integrate", "mesh", "report's relighting model", "hsh / ptm fits + writes",
            "report.html"} <= set(table)
    wall, cpu = table["total"][:2]
    stages = [v for k, v in table.items() if k not in ("rest", "total") and not k.startswith(WITHIN)]
    # run one after the other: each starts after the one before ended, and their CPU is part of the total
    assert all(0 <= s[2] <= s[3] <= wall for s in stages)
    assert sum(s[1] for s in stages) <= cpu + 1e-6 and table["rest"][1] >= -1e-6
    assert proc.ThreadPoolExecutor is pool and whole.photometric_stereo is solve


def test_viewer_psnr_is_higher_with_the_model_at_every_pixel(tmp_path):
    rows = viewer_rows(_scan(tmp_path), [1100, 10])
    (side0, *_, full, _), (side1, *_, coarse, _) = rows
    assert side0 == 1100 and side1 == 10
    assert np.isfinite(full) and full > coarse + 3 and full > 25


def test_the_parts_of_photometric_stereo_are_counted_inside_their_stage(tmp_path):
    # li_alternating coarse-to-fine (coarse_pixels): its full-size round is a part of the solve's row
    table = stage_table(_scan(tmp_path), outputs=["normals"], ps_options={"coarse_pixels": 400})
    solve = table["photometric stereo (solve)"]
    part = table[WITHIN + "solve's full-size round (fine_round) (photometric stereo (solve))"]
    assert solve[2] <= part[2] <= part[3] <= solve[3] and part[1] <= solve[1] + 1e-6
    assert any(k.startswith(WITHIN + "model's coarse rounds") for k in table)
    stages = sum(v[1] for k, v in table.items() if k not in ("rest", "total") and not k.startswith(WITHIN))
    assert abs(table["rest"][1] - (table["total"][1] - stages)) < 1e-9
