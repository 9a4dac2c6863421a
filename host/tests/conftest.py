"""Fixtures shared by several test folders."""
import json
import shutil
import subprocess
from pathlib import Path

import pytest

GLTF_VALIDATOR = Path(__file__).resolve().parents[2] / "tools" / "gltf-validator"


@pytest.fixture(scope="session")
def khronos_validate():
    """validate(path) -> the Khronos glTF validator's report (dict) of a .glb/.gltf file.
    Needs node and `make setup` (npm ci in tools/gltf-validator, from its lock file)."""
    node = shutil.which("node")
    assert node, "node is not installed: run `make setup` (tools/install-debian-deps.sh installs it)"
    assert (GLTF_VALIDATOR / "node_modules" / "gltf-validator").is_dir(), \
        "the glTF validator is not installed: run `make setup` (npm ci in tools/gltf-validator)"

    def validate(path):
        run = subprocess.run([node, str(GLTF_VALIDATOR / "validate.js"), str(path)],
                             capture_output=True, text=True, timeout=120)
        assert run.returncode in (0, 1), run.stderr
        return json.loads(run.stdout)
    return validate


@pytest.fixture(scope="module")
def sim_device():
    """The real firmware core over a pty (build/posix/facette-device, no rig simulator), one per
    test module: ``.port`` is what a DeviceClient or `facette device --port` opens."""
    from facette.sim.device_process import SimulatedDevice

    dev = SimulatedDevice(speed=50, side=False)
    yield dev
    dev.close()


@pytest.fixture
def unchanged():
    """unchanged(*paths): a context manager that sha256s every file under `paths` before and
    after its block and fails when one changed, went or came (a command's inputs are never
    written). Issue 51's tests wrap every case in it."""
    import importlib.util
    spec = importlib.util.spec_from_file_location("_unchanged", Path(__file__).with_name("_unchanged.py"))
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod.unchanged


@pytest.fixture
def force_bands(monkeypatch):
    """force_bands(rows): a --memory run reads its small capture over bands of `rows` rows, as a
    capture larger than its budget is read: its whole reading said not to fit the budget
    (`pipeline._streamed.read_in_bands`), its bands `rows` high (`pipeline._tiles.rows_per_tile`)."""
    from facette.pipeline import _streamed, _tiled_process

    def force(rows):
        monkeypatch.setattr(_streamed, "whole_bytes", lambda *size: float("inf"))
        monkeypatch.setattr(_tiled_process, "rows_per_tile", lambda *a, **k: rows)
    return force
