"""Shared fixtures of the pipeline tests."""
import pytest

from facette.bench._sim_scan import write_scan
from facette.pipeline import process
from facette.recon.synthetic import render, sphere_on_plane, thesis_light_directions


@pytest.fixture(scope="session")
def simulated_result(tmp_path_factory):
    """`process` on a small simulated scan (a satin sphere on a plane, with truth), every output
    but the mesh. Returns (ProcessResult, path of report.html)."""
    root = tmp_path_factory.mktemp("simulated")
    sc = sphere_on_plane(48, 64)
    write_scan(root / "scan", sc, render(sc, thesis_light_directions(), "satin", noise=0.002))
    res = process(root / "scan", outputs=["normals", "albedo", "height", "samples", "brdf", "report"],
                  out_dir=root / "out")
    return res, root / "out" / "report.html"
