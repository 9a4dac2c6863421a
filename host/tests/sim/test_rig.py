"""The rig simulator on a scripted side channel (the event lines of firmware/ports/posix/hal_posix.c).

The device end is a Unix socket driven by the test, so every charge and every
answer line can be checked exactly; the same simulator runs against the real
posix device in hil_tests/.
"""
import socket
import threading

import numpy as np
import pytest

from facette.camera.raw import read_exposure_metadata, read_raw_mosaic
from facette.sim.rig import Faults, RigSimulator, SimCamera
from facette.camera.sensor import SensorModel


class ScriptedDevice:
    """Plays event lines; collects what the simulator answers."""

    def __init__(self, path):
        self.srv = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
        self.srv.bind(str(path))
        self.srv.listen(1)
        self.conn = None
        self.got = []
        self._buf = b""
        self._accepted = threading.Event()
        threading.Thread(target=self._accept, daemon=True).start()

    def _accept(self):
        self.conn, _ = self.srv.accept()
        self._accepted.set()

    def _wait_connected(self):
        assert self._accepted.wait(timeout=10), "the simulator never connected"

    def event(self, line, expect_ack=True):
        """Send one event; when it needs an ack, read answer lines up to and including it."""
        self._wait_connected()
        self.conn.sendall((line + "\n").encode())
        out = []
        if not expect_ack:
            return out
        self.conn.settimeout(10)
        while True:
            while b"\n" not in self._buf:
                self._buf += self.conn.recv(4096)
            ln, self._buf = self._buf.split(b"\n", 1)
            ln = ln.decode()
            out.append(ln)
            self.got.append(ln)
            if ln == "ack":
                return out

    def read_lines(self, n):
        self._wait_connected()
        self.conn.settimeout(10)
        out = []
        while len(out) < n:
            while b"\n" not in self._buf:
                self._buf += self.conn.recv(4096)
            ln, self._buf = self._buf.split(b"\n", 1)
            out.append(ln.decode())
        return out

    def close(self):
        if self.conn:
            self.conn.close()
        self.srv.close()


NOISELESS = SensorModel(gain_e_per_dn=1.0, read_noise_e=0.0, dark_current_e_per_s=0.0, black_level_dn=100,
                        white_level_dn=16383, full_well_e=1e9)


@pytest.fixture
def rig(tmp_path):
    dev = ScriptedDevice(tmp_path / "side.sock")
    radiance = np.zeros((3, 12, 12, 3))
    radiance[0] = 1e-3          # LED 0: 1e-3 e- per mA·µs everywhere
    radiance[1] = 2e-3
    cams = {}

    def make(faults=None):
        cam = SimCamera(tmp_path / "camera", radiance, sensor=NOISELESS, iso=400)
        sim = RigSimulator(tmp_path / "side.sock", cam, faults or Faults(), shutter_lag_us=40)
        cams["sim"] = sim
        return sim, cam

    yield dev, make
    if "sim" in cams:
        cams["sim"].close()
    dev.close()


def _expected_dn(charge_e):
    # shot noise is Poisson even on the noiseless sensor: compare means
    return 100 + charge_e


def test_camera_timed_frame_integrates_current_times_time(rig, tmp_path):
    dev, make = rig
    sim, cam = make()
    assert dev.event("1000 led 0 500") == ["ack"]
    out = dev.event("1100 shutter 1 frame=0 light=0 exp=0 exp_us=20000 mode=camera")
    assert out == ["sync 1140", "ack"]                       # flash sync after the shutter lag
    dev.event("1200 shutter 0 frame=0 light=0 exp=0 exp_us=20000 mode=camera")
    dev.event("21100 led -1 0")                              # light off exactly at the end
    files = sorted((tmp_path / "camera").glob("*.dng"))
    assert len(files) == 1
    mosaic = read_raw_mosaic(files[0])[0]
    charge = 500 * 20000 * 1e-3                              # mA × µs × e-/(mA·µs) = 10000 e-
    # Poisson: σ = 100 e- per pixel, 576 pixels → σ of the mean ≈ 4.2 DN; allow 5σ
    assert abs(mosaic.astype(float).mean() - _expected_dn(charge)) < 21
    t, iso, extra = read_exposure_metadata(files[0])
    assert t == pytest.approx(0.02) and iso == 400
    assert extra["light"] == 0 and extra["exp_us"] == 20000 and extra["mode"] == "camera"
    assert sim.frames[0]["charge_mA_us"][0] == pytest.approx(500 * 20000)


def test_led_mode_counts_only_the_pulse_inside_the_window(rig, tmp_path):
    dev, make = rig
    sim, cam = make()
    dev.event("0 shutter 1 frame=0 light=1 exp=0 exp_us=3000 mode=led")
    dev.event("100000 led 1 200")
    dev.event("103000 led -1 0")
    dev.event("153000 shutter 0 frame=0 light=1 exp=0 exp_us=3000 mode=led")
    assert sim.frames[0]["charge_mA_us"] == pytest.approx([0, 200 * 3000, 0])
    assert sim.frames[0]["window_us"] == 153000


def test_missed_sync_fault_fires_no_sync_and_writes_no_file(rig, tmp_path):
    dev, make = rig
    sim, cam = make(Faults(miss_sync_shots=(0,)))
    out = dev.event("0 shutter 1 frame=0 light=0 exp=0 exp_us=1000 mode=bulb")
    assert out == ["ack"]
    dev.event("1000 shutter 0 frame=0 light=0 exp=0 exp_us=1000 mode=bulb")
    out = dev.event("2000 shutter 1 frame=0 light=0 exp=0 exp_us=1000 mode=bulb")   # the retry
    assert out == ["sync 2040", "ack"]
    dev.event("3000 shutter 0 frame=0 light=0 exp=0 exp_us=1000 mode=bulb")
    assert len(list((tmp_path / "camera").glob("*.dng"))) == 1
    assert sim.missed[0]["why"] == "missed flash sync"


def test_reset_fault_acks_then_resets_and_faults_are_sent_first(rig):
    dev, make = rig
    sim, cam = make(Faults(reset_at_shot=1, biterr=1e-3, open_led=2, overtemp_at_shot=0, overtemp_c=90))
    first = dev.read_lines(2)
    assert first == ["biterr 0.001", "led_fault 2 open"]
    out = dev.event("0 shutter 1 frame=0 light=0 exp=0 exp_us=1000 mode=bulb")
    assert out == ["ntc 9000", "sync 40", "ack"]
    dev.event("1000 shutter 0 frame=0 light=0 exp=0 exp_us=1000 mode=bulb")
    out = dev.event("2000 shutter 1 frame=1 light=0 exp=1 exp_us=1000 mode=bulb")
    assert out == ["ack"]
    assert dev.read_lines(1) == ["reset"]
    dev.event("0 boot 2", expect_ack=False)
    dev.event("10 led 0 100")
    assert sim.boots == [2]


def test_fault_spec_parsing():
    f = Faults.parse("biterr=1e-3,reset_at_shot=5,miss_sync_shots=3:7,open_led=2,overtemp_at_shot=4")
    assert (f.biterr, f.reset_at_shot, f.miss_sync_shots, f.open_led, f.overtemp_at_shot) == \
        (1e-3, 5, (3, 7), 2, 4)
    with pytest.raises(ValueError, match="unknown fault"):
        Faults.parse("lightning=1")
