"""End to end on the simulated rig (posix device + rig simulator): meter, plan, scan, merge.

The merged HDR must equal the renderer's radiance (known truth) within the variance
it reports, through the real device, DNG files, decode and scan.json.
"""
import numpy as np

import facette
from facette.camera.raw import read_raw
from facette.hdr import plan_adaptive
from facette.scan import load_hdr, merge_scan

LIGHTS = [0, 3, 7]


def test_meter_plan_scan_merge_matches_truth(tmp_path):
    with facette.connect("sim", raw_shape=(48, 64), seed=3) as rig:
        sensor = rig.sim.sensor
        truth = rig.sim.radiance[LIGHTS] / sensor.gain_e_per_dn  # DN per µs·mA
        # 1. Metering: one LED-defined frame per light.
        meter = (100_000, 500)
        m = rig.scan(tmp_path / "meter", exposures=[meter], lights=LIGHTS, mode="led",
                     progress=False)
        meter_dir = getattr(m, "path", tmp_path / "meter")
        frames = sorted(read_scan_frames(meter_dir), key=lambda f: f["light"])
        meters = [read_raw(meter_dir / f["file"]) for f in frames]
        # 2. Plan: one exposure list for every light, as the device runs it.
        plan = plan_adaptive(meters, [meter] * len(LIGHTS), sensor, target_snr_db=35.0,
                             shared=True, mode="led")
        assert all(p["target_met"] for p in plan.predicted)
        # 3. Scan with the plan, merge, compare with the renderer's radiance.
        scan = rig.scan(tmp_path / "scan", lights=LIGHTS, progress=False, **plan.scan_kwargs())
    scan_dir = getattr(scan, "path", tmp_path / "scan")
    rec = merge_scan(scan_dir, sensor=sensor)
    assert [l["index"] for l in rec["lights"]] == [0, 1, 2]
    images, variances, lights = load_hdr(scan_dir)
    assert images.shape == truth.shape
    sel = truth > 0.05 * truth.max()
    z = (images - truth)[sel] / np.sqrt(variances[sel])
    assert abs(np.median(images[sel] / truth[sel]) - 1) < 0.01
    assert abs(z.mean()) < 0.2 and 0.8 < z.std() < 1.25


def read_scan_frames(scan_dir):
    import json
    return json.loads((scan_dir / "scan.json").read_text())["frames"]
