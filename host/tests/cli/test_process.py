"""`facette process` on DiLiGenT-style folders made here: the happy path, and every bad input
ends in a clear message with its exit code (2 bad input, 3 data that cannot give a result)."""
import json
import os
from pathlib import Path

import numpy as np
import pytest

from facette.io.checksum import sha256_file
from facette.io.diligent import write_diligent
from facette.recon.synthetic import render, sphere_on_plane, thesis_light_directions

from . import run_cli

L = thesis_light_directions()


def _folder(root, name, u16=None, mask=None):
    sc = sphere_on_plane(24, 32)
    if u16 is None:
        imgs = render(sc, L, "matte")
        u16 = np.round(imgs / imgs.max() * 50000).astype(np.uint16)
    folder = root / name
    write_diligent(folder, u16, L, None, sc.mask if mask is None else mask)
    return folder


@pytest.fixture(scope="module")
def folders(tmp_path_factory):
    root = tmp_path_factory.mktemp("dil")
    good = _folder(root, "good")
    return {"good": good,
            "black": _folder(root, "black", np.zeros((12, 24, 32, 3), np.uint16)),
            "saturated": _folder(root, "saturated", np.full((12, 24, 32, 3), 65535, np.uint16)),
            "empty_mask": _folder(root, "empty_mask", mask=np.zeros((24, 32), bool))}


def test_happy_path_writes_the_outputs_and_their_record(capsys, folders, tmp_path):
    code, out, err = run_cli(capsys, "process", folders["good"], "-o", tmp_path / "r", "--outputs",
                             "normals,mask,height,mesh")
    assert code == 0, err
    assert "diligent" in out and "valid pixels" in out
    rec = json.loads((tmp_path / "r" / "process.json").read_text())
    assert rec["files"] == ["height.exr", "mask.png", "mesh.ply", "normal.exr"]
    assert rec["quality"]["pixels_with_enough_lights"] > 0.9 and rec["scan_incomplete"] is None


def test_interreflections_flag_reports_what_was_gathered(capsys, folders, tmp_path):
    # a sphere on a plane (the plane near the sphere sees its side), its intensities calibrated
    # so that the albedo is a reflectance
    sc = sphere_on_plane(24, 32)
    imgs = render(sc, L, "matte")
    k = 50000 / imgs.max()
    folder = tmp_path / "calibrated"
    write_diligent(folder, np.round(imgs * k).astype(np.uint16), L, np.full((12, 3), k / 65535), sc.mask)
    code, out, err = run_cli(capsys, "process", folder, "-o", tmp_path / "r", "--outputs", "normals",
                             "--interreflections")
    assert code == 0, err
    assert "inter-reflections:" in out and "95th percentile" in out
    rec = json.loads((tmp_path / "r" / "process.json").read_text())
    assert rec["options"]["interreflections"] is True
    # the same images with relative intensities: the albedo's scale is estimated from them
    code, out, err = run_cli(capsys, "process", folders["good"], "-o", tmp_path / "r2", "--outputs",
                             "normals", "--interreflections")
    assert code == 0 and "inter-reflections" in out, err
    assert json.loads((tmp_path / "r2" / "process.json").read_text())["options"]["interreflections"] is True
    # by default ('auto') a DiLiGenT folder keeps its light where the images do not tell the albedo's
    # scale (this sphere on a plane: its albedo does not grow with the light it gathers), recorded as
    # such; --no-interreflections records False
    for flag, recorded in (([], "auto"), (["--no-interreflections"], False)):
        code, out, err = run_cli(capsys, "process", folder, "-o", tmp_path / f"r_{recorded}", "--outputs", "normals",
                                 *flag)
        assert code == 0, err
        rec = json.loads((tmp_path / f"r_{recorded}" / "process.json").read_text())
        assert rec["options"]["interreflections"] == recorded and "inter-reflections:" not in out


@pytest.mark.parametrize("name, words", [
    ("black", "below the noise"),
    ("saturated", "are saturated"),
    ("empty_mask", "holds no pixel of the object"),
])
def test_data_that_cannot_carry_normals_exits_3_with_what_to_change(capsys, folders, tmp_path, name, words):
    before = {p.name: sha256_file(p) for p in folders[name].iterdir()}
    code, out, err = run_cli(capsys, "process", folders[name], "-o", tmp_path / "r")
    assert code == 3, (out, err)
    assert words in err and "Traceback" not in err and len(err.splitlines()) == 2
    todo = err.splitlines()[1]
    assert {"black": "lengthen", "saturated": "shorten", "empty_mask": "mask"}[name] in todo
    assert not (tmp_path / "r").exists()                      # nothing written
    assert {p.name: sha256_file(p) for p in folders[name].iterdir()} == before


def test_an_empty_mask_file_given_with_mask_is_named(capsys, folders, tmp_path):
    from facette.io.png import write_mask

    m = tmp_path / "m.png"
    write_mask(m, np.zeros((24, 32), bool))
    code, out, err = run_cli(capsys, "process", folders["good"], "-o", tmp_path / "r", "--mask", m)
    assert code == 3 and f"--mask {m}" in err, err


def test_a_mask_of_another_size_says_both_sizes(capsys, folders, tmp_path):
    from facette.io.png import write_mask

    m = tmp_path / "m.png"
    write_mask(m, np.ones((10, 10), bool))
    code, out, err = run_cli(capsys, "process", folders["good"], "-o", tmp_path / "r", "--mask", m)
    assert code == 2 and "10x10" in err and "32x24" in err, err


@pytest.mark.parametrize("args, words", [
    (["--mesh-step", "0"], "--mesh-step must be >= 1"),
    (["--pixel-pitch", "0"], "--pixel-pitch must be > 0"),
    (["--pixel-pitch", "nan"], "--pixel-pitch must be > 0"),
    (["--t-ombre", "-0.5"], "--t-ombre must be in (0, 1.5708]"),
    (["--t-spec", "0"], "--t-spec must be > 0"),
    (["--theta0", "120"], "--theta0 must be in (0, 90]"),
    (["--outputs", "normals,shape"], "unknown output(s) shape"),
    (["--brdf-model", "phong"], "invalid choice: 'phong'"),
    (["--method", "x"], "invalid choice: 'x'"),
])
def test_bad_options_are_refused_before_any_work(capsys, folders, tmp_path, args, words):
    code, out, err = run_cli(capsys, "process", folders["good"], "-o", tmp_path / "r", *args)
    assert code == 2 and words in err and len(err.splitlines()) == 2, err
    assert not (tmp_path / "r").exists()


def test_the_output_is_a_file(capsys, folders, tmp_path):
    f = tmp_path / "f"
    f.write_text("mine")
    code, out, err = run_cli(capsys, "process", folders["good"], "-o", f)
    assert code == 2 and f"-o {f} is a file" in err and f.read_text() == "mine", err
    code, out, err = run_cli(capsys, "process", folders["good"], "-o", f / "out")   # under a file
    assert code == 2 and f"{f} is a file, not a folder" in err and f.read_text() == "mine", err


def test_the_output_is_not_writable(capsys, folders, tmp_path):
    if os.geteuid() == 0:
        target = Path("/sys/facette-results")       # root ignores permission bits; sysfs refuses
    else:
        ro = tmp_path / "ro"
        ro.mkdir()
        ro.chmod(0o500)
        target = ro / "r"
    code, out, err = run_cli(capsys, "process", folders["good"], "-o", target)
    assert code == 2 and str(target) in err and "write" in err and "Traceback" not in err, err


def test_a_results_folder_holds_one_run(capsys, folders, tmp_path):
    out = tmp_path / "r"
    assert run_cli(capsys, "process", folders["good"], "-o", out, "--outputs", "normals,mesh")[0] == 0
    first = sha256_file(out / "normal.exr")
    code, _, err = run_cli(capsys, "process", folders["good"], "-o", out, "--outputs", "normals",
                           "--t-ombre", "1.2")
    assert code == 2 and "holds the results of another run (t_ombre: 1.5 then, 1.2 now)" in err, err
    assert sha256_file(out / "normal.exr") == first            # untouched
    code, _, err = run_cli(capsys, "process", folders["good"], "-o", out, "--outputs", "normals",
                           "--t-ombre", "1.2", "--overwrite")
    assert code == 0, err
    assert sorted(p.name for p in out.iterdir()) == ["normal.exr", "process.json"]   # mesh.ply was the other run's
    assert json.loads((out / "process.json").read_text())["options"]["t_ombre"] == 1.2
    # the same options again, other outputs: both runs' files are one run's
    assert run_cli(capsys, "process", folders["good"], "-o", out, "--outputs", "mask",
                   "--t-ombre", "1.2")[0] == 0
    assert json.loads((out / "process.json").read_text())["files"] == ["mask.png", "normal.exr"]


def test_a_folder_of_foreign_files_is_not_written_into(capsys, folders, tmp_path):
    out = tmp_path / "r"
    out.mkdir()
    (out / "notes.txt").write_text("mine")
    code, _, err = run_cli(capsys, "process", folders["good"], "-o", out)
    assert code == 2 and "no facette process run recorded" in err, err
    assert sorted(p.name for p in out.iterdir()) == ["notes.txt"]


@pytest.mark.parametrize("table, text, words", [
    ("light_directions.txt", "0 0 1\n0 x 1\n", "light_directions.txt, line 2: '0 x 1' is not 3 finite numbers"),
    ("light_directions.txt", "0 0 1\n", "light_directions.txt holds 1 lines of 3 numbers; filenames.txt lists 12"),
    ("light_directions.txt", "nan 0 1\n" * 12, "line 1: 'nan 0 1' is not 3 finite numbers"),
    ("light_intensities.txt", "1 1 1\n" * 11 + "1 0 1\n", "light_intensities.txt, line 12: a non-positive"),
])
def test_a_bad_line_in_a_diligent_table_is_named(capsys, folders, tmp_path, table, text, words):
    import shutil

    bad = tmp_path / "bad"
    shutil.copytree(folders["good"], bad)
    (bad / table).write_text(text)
    code, out, err = run_cli(capsys, "process", bad, "-o", tmp_path / "r")
    assert code == 2 and words in err and "calibration profile" not in err, err


def test_a_source_that_is_neither_kind_of_folder(capsys, tmp_path):
    code, _, err = run_cli(capsys, "process", tmp_path, "-o", tmp_path / "r")
    assert code == 2 and "holds neither scan.json" in err, err
    code, _, err = run_cli(capsys, "process", tmp_path / "nope", "-o", tmp_path / "r")
    assert code == 2 and "is not a directory" in err, err


def test_a_brdf_fit_needs_enough_filled_cells(capsys, tmp_path):
    """A flat slab under 4 lights fills a handful of hemisphere cells: no BRDF can be fitted
    from that, and saying "ok" would be a lie (exit 3, with what to change)."""
    from facette.recon.synthetic import Scene

    h, w = 24, 32
    n = np.zeros((h, w, 3))
    n[..., 2] = 1
    flat = Scene(n, np.zeros((h, w)), np.ones((h, w), bool), np.zeros((h, w), bool), (12, 16), 1.0)
    lights = L[[0, 3, 6, 9]]
    imgs = render(flat, lights, "matte")
    u16 = np.round(imgs / imgs.max() * 50000).astype(np.uint16)
    write_diligent(tmp_path / "flat", u16, lights, None, flat.mask)
    code, out, err = run_cli(capsys, "process", tmp_path / "flat", "-o", tmp_path / "r", "--outputs", "brdf")
    assert code == 3 and "a BRDF fit needs 10 filled cells" in err and "more lights" in err, err
    code, out, err = run_cli(capsys, "process", tmp_path / "flat", "-o", tmp_path / "r2", "--outputs", "normals")
    assert code == 0, err                                   # the normals it can give


def test_the_default_brdf_model_is_the_one_photometric_stereo_found(tmp_path, capsys):
    # Cook–Torrance images (a Lambertian term beside the lobe): photometric stereo finds that diffuse
    # part, and `facette process` without --brdf-model fits Cook–Torrance first ("auto"), not the LI
    # model it once forced on every material
    sc = sphere_on_plane(64, 64)
    imgs = render(sc, L, "glossy", noise=0.005, rng=np.random.default_rng(3))
    folder = tmp_path / "glossy"
    write_diligent(folder, np.round(imgs / imgs.max() * 50000).astype(np.uint16), L, None, sc.mask)
    code, out, err = run_cli(capsys, "process", folder, "-o", tmp_path / "o", "--outputs", "normals,samples,brdf")
    assert code == 0, err
    doc = json.loads((tmp_path / "o" / "brdf.json").read_text())
    assert doc["photometric_stereo"]["materials"][0]["diffuse"] == "lambert"
    assert doc["model"] == "cook_torrance" and doc["models_tried"][0]["model"] == "cook_torrance", doc["models_tried"]
    assert abs(doc["parameters"]["sigma"] - 0.05) < 0.01


# ---------------------------------------------------------------- issue 51: values checked, advice that works
def _free_port():
    import socket
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@pytest.mark.parametrize("args, words", [
    (["--memory", "1TB"], "more than this machine's"),
    (["--memory", "5000GB"], "more than this machine's"),
    (["--memory", "0GB"], "at least 1 byte"),
    (["--memory", "2 apples"], "a size such as 2GB"),
    (["--scheduler", "udp://host:8786", "--memory", "2GB"], "not a scheduler's address"),
    (["--scheduler", "tcp://:8786", "--memory", "2GB"], "not a scheduler's address"),
])
def test_sizes_and_addresses_are_checked_before_any_work(capsys, folders, tmp_path, unchanged, args, words):
    with unchanged(folders["good"], tmp_path):
        code, out, err = run_cli(capsys, "process", folders["good"], "-o", tmp_path / "r", *args)
    assert code == 2 and words in err and len(err.splitlines()) == 2, err
    assert not (tmp_path / "r").exists()


def test_a_scheduler_nothing_listens_at_is_bad_input_not_a_bug(capsys, folders, tmp_path, unchanged):
    address = f"tcp://127.0.0.1:{_free_port()}"
    with unchanged(folders["good"], tmp_path):
        code, out, err = run_cli(capsys, "process", folders["good"], "-o", tmp_path / "r", "--memory", "2GB",
                                 "--scheduler", address)
    assert code == 2 and f"--scheduler {address}: nothing listens at" in err and "Traceback" not in err, err
    assert "leave --scheduler out" in err
    with unchanged(folders["good"]):               # the hint followed: without --scheduler it runs here
        assert run_cli(capsys, "process", folders["good"], "-o", tmp_path / "r", "--memory", "2GB",
                       "--outputs", "normals")[0] == 0


def test_ctrl_c_says_what_the_same_command_does_and_it_does(capsys, folders, tmp_path, unchanged, monkeypatch):
    import facette.pipeline._process as proc

    def interrupt(*a, **k):
        raise KeyboardInterrupt
    argv = ["process", folders["good"], "-o", tmp_path / "r", "--outputs", "normals,mask", "--method", "woodham1980"]
    with unchanged(folders["good"]):
        with monkeypatch.context() as m:
            m.setattr(proc, "write_mask", interrupt)
            code, out, err = run_cli(capsys, *argv)
        assert code == 130 and "the same command redoes it" in err and "scan resumes" not in err, err
        assert json.loads((tmp_path / "r" / "process.json").read_text())["state"] == "running"
        code, out, err = run_cli(capsys, *argv)       # what the message says: the same command
    assert code == 0, err
    assert json.loads((tmp_path / "r" / "process.json").read_text())["state"] == "done"
    assert sorted(p.name for p in (tmp_path / "r").iterdir()) == ["mask.png", "normal.exr", "process.json"]


def test_foreign_files_hint_works(capsys, folders, tmp_path, unchanged):
    out = tmp_path / "r"
    out.mkdir()
    (out / "notes.txt").write_text("mine")
    with unchanged(folders["good"], out):
        code, _, err = run_cli(capsys, "process", folders["good"], "-o", out, "--outputs", "normals")
    assert code == 2 and "--overwrite to write beside them" in err
    with unchanged(folders["good"]):
        assert run_cli(capsys, "process", folders["good"], "-o", out, "--outputs", "normals", "--overwrite")[0] == 0
    assert (out / "notes.txt").read_text() == "mine" and (out / "normal.exr").is_file()   # beside them


def test_the_input_folder_as_output_hint_works(capsys, folders, tmp_path, unchanged):
    import shutil
    src = tmp_path / "src"
    shutil.copytree(folders["good"], src)
    with unchanged(src):
        code, _, err = run_cli(capsys, "process", src, "-o", src, "--outputs", "normals")
        assert code == 2 and "never writes its inputs" in err
        hinted = err.split("e.g. ")[1].split()[0]
        assert hinted == str(tmp_path / "src-results")
        assert run_cli(capsys, "process", src, "-o", hinted, "--outputs", "normals")[0] == 0


def test_a_damaged_record_hint_works(capsys, folders, tmp_path, unchanged):
    out = tmp_path / "r"
    out.mkdir()
    (out / "process.json").write_text("{not json")
    with unchanged(folders["good"], out):
        code, _, err = run_cli(capsys, "process", folders["good"], "-o", out, "--outputs", "normals")
    assert code == 2 and "process.json is damaged" in err and "pass --overwrite" in err, err
    with unchanged(folders["good"]):               # the hint followed
        code, _, err = run_cli(capsys, "process", folders["good"], "-o", out, "--outputs", "normals", "--overwrite")
    assert code == 0, err
    assert json.loads((out / "process.json").read_text())["state"] == "done"


def test_a_mask_inside_the_output_folder_hint_works(capsys, folders, tmp_path, unchanged):
    import shutil
    out = tmp_path / "r"
    out.mkdir()
    shutil.copy(folders["good"] / "mask.png", out / "m.png")
    with unchanged(folders["good"], out):
        code, _, err = run_cli(capsys, "process", folders["good"], "-o", out, "--mask", out / "m.png",
                               "--outputs", "normals")
    assert code == 2 and "keep the mask elsewhere" in err, err
    shutil.move(out / "m.png", tmp_path / "m.png")   # the hint followed
    with unchanged(folders["good"], tmp_path / "m.png"):
        assert run_cli(capsys, "process", folders["good"], "-o", out, "--mask", tmp_path / "m.png",
                       "--outputs", "normals")[0] == 0
