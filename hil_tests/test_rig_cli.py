"""The command line: `facette sim` (first line `port: <path>`), `facette device`,
`facette scan --sim --press-button` (what `make scan` runs)."""
import hashlib
import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

FACETTE = [sys.executable, "-m", "facette.cli.main"]


def test_facette_sim_prints_its_port_first_and_facette_device_talks_to_it(tmp_path):
    with subprocess.Popen(FACETTE + ["sim", "--raw-size", "128x96", "--speed", "100", "--workdir", str(tmp_path / "sim")],
                          stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                          text=True) as sim:
        _talk(sim)
    assert sim.returncode == 0


def _talk(sim):
    try:
        first = sim.stdout.readline()
        assert first.startswith("port: /")
        port = first.split(": ", 1)[1].strip()
        assert sim.stdout.readline().startswith("camera: ")
        out = subprocess.run(FACETTE + ["device", "--port", port, "info"], capture_output=True, text=True,
                             timeout=60)
        assert out.returncode == 0, out.stderr
        info = json.loads(out.stdout)
        assert info["identification"]["vendor"] == "facette" and info["boot_count"] >= 1
        out = subprocess.run(FACETTE + ["device", "--port", port, "write", "gap_us", "250000"],
                             capture_output=True, text=True, timeout=60)
        assert json.loads(out.stdout) == {"gap_us": 250000}
        bad = subprocess.run(FACETTE + ["device", "--port", port, "write", "n_lights", "99"],
                             capture_output=True, text=True, timeout=60)
        assert bad.returncode != 0 and "out of range" in bad.stderr
    finally:
        sim.stdin.write("quit\n")
        sim.stdin.flush()
        sim.wait(timeout=30)


def test_facette_scan_sim_press_button(tmp_path):
    out_dir = tmp_path / "demo"
    run = subprocess.run(FACETTE + ["scan", "--sim", "--press-button", "--no-process", "--quiet", "--raw-size", "128x96",
                                    "--exposures", "1/5,1/50", "--lights", "0,1,2,3", str(out_dir)],
                         capture_output=True, text=True, timeout=300, cwd=tmp_path)
    assert run.returncode == 0, run.stderr
    assert "scan: 8 frames" in run.stdout and f"results: {out_dir}" in run.stdout
    m = json.loads((out_dir / "scan.json").read_text())
    assert [e["time_us"] for e in m["exposures"]] == [200000, 20000] and m["complete"]
    truth = np.load(out_dir / "truth.npz")
    assert truth["light_dirs"].shape == (4, 3)
    # the same command again resumes: nothing left to take, nothing retaken
    again = subprocess.run(FACETTE + ["scan", "--sim", "--press-button", "--no-process", "--quiet", "--raw-size", "128x96",
                                      "--exposures", "1/5,1/50", "--lights", "0,1,2,3", str(out_dir)],
                           capture_output=True, text=True, timeout=300, cwd=tmp_path)
    assert again.returncode == 0, again.stderr
    assert json.loads((out_dir / "scan.json").read_text())["frames"] == m["frames"]
    assert Path(out_dir / "raw").is_dir()


def test_scan_a_rig_through_its_port_and_camera_folder(tmp_path):
    """The real-rig path: `facette scan --device PORT --camera-dir DIR` (no simulator object in
    the host: the rig is a separate `facette sim` process, as a real rig would be)."""
    with subprocess.Popen(FACETTE + ["sim", "--raw-size", "128x96", "--speed", "200", "--workdir", str(tmp_path / "rig")],
                          stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                          text=True) as sim:
        try:
            port = sim.stdout.readline().split(": ", 1)[1].strip()
            camera = sim.stdout.readline().split(": ", 1)[1].strip()
            run = subprocess.run(FACETTE + ["scan", "--device", port, "--camera-dir", camera, "--exposures",
                                            "1/5,1/50", "--lights", "0,1,2", "--no-process", "--quiet",
                                            str(tmp_path / "scan")], capture_output=True, text=True, timeout=300)
        finally:
            sim.stdin.write("quit\n")
            sim.stdin.flush()
            sim.wait(timeout=30)
    assert run.returncode == 0, run.stderr
    m = json.loads((tmp_path / "scan" / "scan.json").read_text())
    assert len(m["frames"]) == 6 and m["truth"] is None and m["complete"]
    assert sorted(p.name for p in (tmp_path / "scan" / "raw").glob("*.dng")) == \
        [f"L{l:02d}_E{e:02d}.dng" for l in range(3) for e in range(2)]


def test_files_that_predate_the_scan_stay_in_the_camera_folder_across_a_resume(tmp_path):
    from facette.sim.dng import write_dng

    with subprocess.Popen(FACETTE + ["sim", "--raw-size", "128x96", "--speed", "200", "--workdir", str(tmp_path / "rig")],
                          stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                          text=True) as sim:
        try:
            port = sim.stdout.readline().split(": ", 1)[1].strip()
            camera = Path(sim.stdout.readline().split(": ", 1)[1].strip())
            holiday = camera / "HOLIDAY.dng"             # someone's earlier photo on the card
            write_dng(holiday, np.full((24, 24), 700, np.uint16), 512, 16383, 1 / 100, 200)
            args = FACETTE + ["scan", "--device", port, "--camera-dir", str(camera), "--exposures", "1/50",
                              "--lights", "0,1", "--no-process", "--quiet", str(tmp_path / "scan")]
            first = subprocess.run(args, capture_output=True, text=True, timeout=300)
            (tmp_path / "scan" / "raw" / "L01_E00.dng").unlink()   # a frame lost: the resume retakes it
            again = subprocess.run(args, capture_output=True, text=True, timeout=300)
        finally:
            sim.stdin.write("quit\n")
            sim.stdin.flush()
            sim.wait(timeout=30)
    assert first.returncode == 0 and again.returncode == 0, first.stderr + again.stderr
    assert holiday.is_file()                               # not taken, not moved
    assert not (tmp_path / "scan" / "raw" / "unmatched").exists()
    assert (tmp_path / "scan" / "raw" / "L01_E00.dng").is_file()


def test_a_scan_stopped_by_a_fault_says_why_and_exits_1(tmp_path):
    run = subprocess.run(FACETTE + ["scan", "--sim", "--raw-size", "128x96", "--faults", "open_led=1", "--lights", "0,1,2",
                                    "--exposures", "1/50", "--no-process", "--quiet", str(tmp_path / "s")],
                         capture_output=True, text=True, timeout=300)
    assert run.returncode == 1
    assert "LED_OPEN" in run.stderr and "run the same scan again to resume" in run.stderr
    assert "Traceback" not in run.stderr
    assert len(json.loads((tmp_path / "s" / "scan.json").read_text())["frames"]) == 1


def test_sim_stops_and_says_so_when_its_firmware_process_dies(tmp_path):
    sim = subprocess.Popen(FACETTE + ["sim", "--raw-size", "64x48", "--workdir", str(tmp_path)],
                           stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        assert sim.stdout.readline().startswith("port: ")
        children = Path(f"/proc/{sim.pid}/task/{sim.pid}/children").read_text().split()
        firmware = [int(c) for c in children
                    if "facette-device" in Path(f"/proc/{c}/cmdline").read_bytes().decode(errors="replace")]
        assert firmware, children
        os.kill(firmware[0], signal.SIGKILL)
        t0 = time.monotonic()
        code = sim.wait(timeout=30)
        err = sim.stderr.read()
        assert code == 1 and time.monotonic() - t0 < 10
        assert "the simulated device's firmware process ended" in err and "start facette sim again" in err
    finally:
        if sim.poll() is None:
            sim.kill()
            sim.wait()
        for f in (sim.stdin, sim.stdout, sim.stderr):
            f.close()


def test_a_scan_across_filesystems_stops_on_a_full_disk_and_resumes_once_space_is_freed(small_disk):
    """The simulator's camera folder on one tmpfs ($TMPDIR), the scan on another, too small for it:
    frames cross filesystems (copy, then rename), the full disk stops the scan (exit 1, the disk
    named), and the same command finishes it once the disk is larger; every frame matches scan.json."""
    camera_tmp = small_disk(64 * 1024, "tmp")     # the fixture (conftest.py) unmounts them after
    disk = small_disk(200, "disk")
    cmd = FACETTE + ["scan", "--sim", "--press-button", "--no-process", "--quiet", "--raw-size", "128x96",
                     "--exposures", "1/5,1/50", "--lights", "0,1,2,3,4,5", str(disk / "scan")]
    env = {**os.environ, "TMPDIR": str(camera_tmp)}
    full = subprocess.run(cmd, capture_output=True, text=True, timeout=300, env=env)
    assert full.returncode == 1, full.stderr
    assert f"(mounted at {disk}) is full" in full.stderr and "the scan resumes where it stopped" in full.stderr
    assert "Traceback" not in full.stderr and "bug" not in full.stderr
    kept = json.loads((disk / "scan" / "scan.json").read_text())["frames"]
    assert 0 < len(kept) < 12
    subprocess.run(["mount", "-o", "remount,size=8m", str(disk)], check=True)
    again = subprocess.run(cmd, capture_output=True, text=True, timeout=300, env=env)
    assert again.returncode == 0, again.stderr
    m = json.loads((disk / "scan" / "scan.json").read_text())
    assert m["complete"] and len(m["frames"]) == 12
    assert {f["file"]: f["sha256"] for f in kept}.items() <= {f["file"]: f["sha256"] for f in m["frames"]}.items()
    for f in m["frames"]:
        assert hashlib.sha256((disk / "scan" / f["file"]).read_bytes()).hexdigest() == f["sha256"]
    assert not list((disk / "scan").rglob("*.partial"))
