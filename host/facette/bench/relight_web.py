"""`facette bench relight_web`: Relight's web format at 12 MP, written by `process` and read back by
`facette relight`: wall and CPU seconds per megapixel and peak memory (each in a process of its own).

The capture is made here: a matte sphere on a textured plane, 4000 x 3000 pixels, 16 lights from
10° to 60° off the axis, as JPEG (q 95) + .lp. Then `facette process --outputs relight-web` (HSH 3,
deep-zoom pyramids), and `facette relight OUT/relight_web` at one light (the reader holds one byte
per coefficient and relights by bands).

`--outputs rti,ptm` (any relighting outputs) times those instead; `--read whole` reads the capture whole (the
run is told the machine has WHOLE_FREE bytes free, as a machine with that much memory would decide),
`--read bands` over bands of BANDS_MEMORY (`--memory`), `--read auto` (default) as this machine decides;
`--capture DIR` reuses a capture this bench made (kept with `--out`).

Usage: facette bench relight_web [--size H W] [--lights M] [--out DIR] [--outputs LIST] [--read auto|whole|bands]
                                 [--capture DIR]
"""
import argparse
import json
import os
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

WHOLE_FREE = 64 * 10 ** 9      # `--read whole`: the free memory the run is told of (its budget then holds 12 MP whole)
BANDS_MEMORY = "4GB"           # `--read bands`: the budget (the default budget's largest bands, BANDS_MAX_BYTES)
# `--read whole`: facette's command with the default budget's reading of the free memory replaced
WHOLE_CHILD = ("import sys; from facette.pipeline import _budget; free = int(sys.argv.pop(1)); "
               "_budget.free_memory = lambda: free; "
               "from facette.cli.main import main; sys.exit(main())")


def _capture(folder, h, w, m):
    """JPEG + .lp capture of a matte sphere on a textured plane, one photograph at a time."""
    import cv2

    from facette.calib.lp import write_lp
    from facette.recon import srgb_encode
    from facette.recon.synthetic import render, sphere_on_plane
    folder.mkdir(parents=True, exist_ok=True)
    az = np.radians(np.arange(m) * 360.0 / m)
    off = np.radians(np.tile([10.0, 25.0, 45.0, 60.0], -(-m // 4))[:m])
    dirs = np.c_[np.sin(off) * np.cos(az), np.sin(off) * np.sin(az), np.cos(off)]
    sc = sphere_on_plane(h, w)
    rng = np.random.default_rng(0)
    patches = rng.uniform(0.6, 1.0, size=(24, 32, 1)).astype(np.float32)
    tex = np.repeat(np.repeat(patches, -(-h // 24), 0), -(-w // 32), 1)[:h, :w]
    names = []
    for k, d in enumerate(dirs):
        img = render(sc, d[None], "matte", albedo=(0.8, 0.7, 0.6), cast_shadows=False)[0] * tex
        names.append(f"img_{k:03d}.jpg")
        shown = srgb_encode(np.clip(img / 0.3, 0, 1)).astype(np.float32)
        cv2.imwrite(str(folder / names[-1]), np.round(shown[..., ::-1] * 255).astype(np.uint8),
                    [cv2.IMWRITE_JPEG_QUALITY, 95])
        del img, shown
    write_lp(folder / "capture.lp", names, dirs)


def _timed(argv, free=None):
    """(wall s, CPU s, peak RSS GB) of `python -m facette.cli.main argv` in a process of its own
    (free: the free memory its default budget is told of, bytes; None: the machine's)."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    t0 = time.perf_counter()
    cmd = [sys.executable, "-m", "facette.cli.main"] if free is None else [sys.executable, "-c", WHOLE_CHILD, str(free)]
    # wait4 gives this child's own peak RSS (RUSAGE_CHILDREN's is the largest child's so far)
    proc = subprocess.Popen(cmd + [*map(str, argv)], stdout=subprocess.DEVNULL)
    _, status, usage = os.wait4(proc.pid, 0)
    wall = time.perf_counter() - t0
    proc.returncode = os.waitstatus_to_exitcode(status)       # reaped here, not by Popen
    if proc.returncode != 0:
        raise SystemExit(f"facette {' '.join(map(str, argv))} failed ({status})")
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    return wall, cpu, usage.ru_maxrss / 1e6


def main(argv=None):
    p = argparse.ArgumentParser(prog="facette bench relight_web", description=__doc__.splitlines()[0])
    p.add_argument("--size", nargs=2, type=int, default=(3000, 4000), metavar=("H", "W"))
    p.add_argument("--lights", type=int, default=16)
    p.add_argument("--out", help="keep the files here (default: a temporary folder)")
    p.add_argument("--outputs", default="relight-web", help="process's --outputs (default relight-web)")
    p.add_argument("--read", choices=("auto", "whole", "bands"), default="auto",
                   help="whole: as a machine with 64 GB free; bands: --memory 4GB; auto: as this machine decides")
    p.add_argument("--capture", help="a capture this bench made before (its size and lights are the capture's)")
    a = p.parse_args(argv)
    h, w = a.size
    mp = h * w / 1e6
    with tempfile.TemporaryDirectory() as tmp:
        base = Path(a.out) if a.out else Path(tmp)
        capture = Path(a.capture) if a.capture else _made(base / "capture", h, w, a.lights)
        if a.capture:
            h, w = _size_of(capture)
            mp = h * w / 1e6
        out = base / "out"
        how = {"auto": [], "whole": [], "bands": ["--memory", BANDS_MEMORY]}[a.read]
        wall, cpu, peak = _timed(["process", capture, "-o", out, "--outputs", a.outputs, "--overwrite", *how],
                                 WHOLE_FREE if a.read == "whole" else None)
        files = [f for f in out.rglob("*") if f.is_file() and f.name != "process.json"]
        size = sum(f.stat().st_size for f in files) / 1e6
        print(f"process --outputs {a.outputs} (read {a.read}): {wall:.1f} s wall ({wall / mp:.2f} s/MP), {cpu:.1f} CPU s "
              f"({cpu / mp:.2f} CPU s/MP), peak {peak:.2f} GB; {len(files)} files, {size:.1f} MB ({size / mp:.2f} MB/MP)")
        if not (out / "relight_web").is_dir():
            return 0
        wall, cpu, peak = _timed(["relight", out / "relight_web", "--light", "45,30", "-o", base / "lit.png",
                                  "--overwrite"])
        layout = json.loads((out / "relight_web" / "info.json").read_text())["layout"]
        print(f"relight OUT/relight_web ({layout}, one light): {wall:.1f} s wall, {cpu:.1f} CPU s, peak {peak:.2f} GB")
    return 0


def _made(folder, h, w, m):
    """The capture made in a process of its own: a child's peak memory starts from its parent's at the
    fork (Linux keeps the high-water mark across exec), so this process stays small."""
    t0 = time.perf_counter()
    subprocess.run([sys.executable, "-c", "import sys; from pathlib import Path; from facette.bench.relight_web "
                    "import _capture; _capture(Path(sys.argv[1]), *map(int, sys.argv[2:]))",
                    str(folder), str(h), str(w), str(m)], check=True)
    print(f"capture: {w}x{h} ({h * w / 1e6:.1f} MP), {m} JPEG photographs, made in {time.perf_counter() - t0:.0f} s")
    return folder


def _size_of(capture):
    """(H, W) of a capture's first photograph (its header only)."""
    from PIL import Image
    with Image.open(sorted(Path(capture).glob("*.jpg"))[0]) as im:
        return im.height, im.width


if __name__ == "__main__":
    raise SystemExit(main())
