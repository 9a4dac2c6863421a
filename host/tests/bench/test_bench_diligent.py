"""`facette bench diligent` (facette.bench.diligent; the file name differs from io's test_diligent.py,
which pytest's rootdir imports would confuse) on a DiLiGenT-style folder written here."""
import numpy as np
import pytest

from facette.bench.diligent import angular_errors, find_objects, main, rig_light_indices
from facette.io.diligent import write_diligent
from facette.recon.synthetic import render, sphere_on_plane, thesis_light_directions


def dome(m=40, seed=1):
    rng = np.random.default_rng(seed)
    d = rng.normal(size=(m, 3))
    d[:, 2] = np.abs(d[:, 2]) + 1.5
    return d / np.linalg.norm(d, axis=1, keepdims=True)


@pytest.fixture
def folder(tmp_path):
    """A matte sphere on a plane under the rig's 12 lights and 28 others, 16-bit PNGs."""
    lights = np.concatenate([thesis_light_directions(), dome(28)])[::-1]
    sc = sphere_on_plane(40, 48)
    imgs = render(sc, lights, "matte", albedo=(0.9, 0.9, 0.9))
    u16 = np.clip(imgs / imgs.max() * 60000, 0, 65535).astype(np.uint16)
    obj = tmp_path / "set" / "spherePNG"
    write_diligent(obj, u16, lights, mask=sc.mask)
    truth = tmp_path / "set" / "spherePNG.truth"
    truth.mkdir()
    gt = sc.normals.astype(np.float32).copy()
    gt[0, 0] = 0                                  # a zero-length truth normal: left out
    np.save(truth / "normals_gt.npy", gt)
    (tmp_path / "set" / "notruthPNG").mkdir()
    write_diligent(tmp_path / "set" / "notruthPNG", u16[:4], lights[:4])
    return tmp_path, lights


def test_rig_lights_are_found_among_others(folder):
    _, lights = folder
    idx, ang = rig_light_indices(lights)
    np.testing.assert_allclose(lights[idx], thesis_light_directions(), atol=1e-9)
    assert ang.max() < 1e-5


def test_bench_prints_a_table_for_each_object_with_truth(folder, capsys):
    root, _ = folder
    assert [t is None for _, t in find_objects(root)] == [True, False]
    assert main(["--root", str(root), "--methods", "woodham1980,rank_trimmed"]) == 0
    out = capsys.readouterr().out
    assert "no truth for" in out and "12 lights near the rig" in out
    rows = [l for l in out.splitlines() if l.startswith("set/sphere 16-bit")]
    assert len(rows) == 2                          # all lights, then 12
    ls_mean, rt_mean = (float(cell.split()[0]) for cell in rows[0].split("|")[1:3])
    assert rt_mean < 0.5 * ls_mean < 5             # shadows: trimming them helps


def test_angular_errors_skip_zero_truth():
    truth = np.zeros((1, 2, 3))
    truth[0, 1] = [0, 0, 1]
    est = np.zeros((1, 2, 3))
    est[0, 1] = [0, 1, 0]
    np.testing.assert_allclose(angular_errors(est, truth, np.ones((1, 2), bool)), [90.0])


def test_bench_without_data_says_where_to_look(tmp_path, capsys):
    assert main(["--root", str(tmp_path)]) == 1
    assert "--root" in capsys.readouterr().out


def test_a_method_with_the_ir_suffix_removes_inter_reflections_first(folder, capsys):
    root, _ = folder
    assert main(["--root", str(root), "--methods", "rank_trimmed,rank_trimmed+ir", "--lights", "12"]) == 0
    out = capsys.readouterr().out
    assert "rank_trimmed+ir" in out
    row = next(l for l in out.splitlines() if l.startswith("set/sphere 16-bit"))
    plain, removed = (float(cell.split()[0]) for cell in row.split("|")[1:3])
    # facette's renderer has no inter-reflections: removing what the sphere and the plane would
    # send each other can only move the normals away from the truth
    assert plain < 0.1 < removed


def test_unknown_methods_are_refused_with_the_choices(folder):
    root, _ = folder
    with pytest.raises(SystemExit, match="unknown method 'nope\\+ir'"):
        main(["--root", str(root), "--methods", "nope+ir"])


def test_bench_figures_are_those_of_process(folder):
    """The bench scores what `facette process` returns (the user's path), also for 12 lights."""
    from facette.bench.diligent import run_object
    from facette.pipeline import process
    root, _ = folder
    obj, truth = root / "set" / "spherePNG", root / "set" / "spherePNG.truth" / "normals_gt.npy"
    rows, _, _ = run_object(obj, truth, ["rank_trimmed"], "all")
    res = process(obj, outputs=["normals"], method="rank_trimmed")
    e = angular_errors(res.normals, np.load(truth), res.inputs.mask)
    assert rows[0][1] == pytest.approx(float(e.mean()), abs=1e-9)


def test_subset_folder_holds_the_chosen_lights(folder, tmp_path):
    from facette.bench.diligent import subset_folder
    from facette.io.diligent import read_diligent
    root, lights = folder
    obj = root / "set" / "spherePNG"
    sel = np.array([5, 1, 30])
    sub = subset_folder(obj, sel, tmp_path / "sub")
    a, b = read_diligent(sub), read_diligent(obj, select=sel)
    np.testing.assert_allclose(a.light_dirs, b.light_dirs, atol=1e-6)
    np.testing.assert_array_equal(a.images, b.images)
    np.testing.assert_array_equal(a.mask, b.mask)
