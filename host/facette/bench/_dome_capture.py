"""`facette bench lights --capture WxH`: the default measured whole on a dome's capture as a user has
it on disk: the relief of `--banded` (Cook-Torrance, 1 % noise, the same photographs: `lights.render_band`)
written once as a DiLiGenT-style folder of 16-bit RGB PNGs (kept with --keep and reused), then
`facette process FOLDER --outputs normals,height` with no flag, in a process of its own: the
product's part (reading the PNGs, the budget's bands, the lights' gains, the model, the per-pixel
solve, the uncertainty, the heights) measured apart from the rendering, which is the bench's input.

Folder: 001.png ... (m files), filenames.txt, light_directions.txt (`lights.dome_lights`),
light_intensities.txt (GAIN), mask.png (the whole frame), normal_gt.npy (the truth).
"""
import json
import os
import sys
import time
from pathlib import Path

import numpy as np

from facette.io.png import PngBandWriter

__all__ = ["write_dome_capture", "measure_capture", "GAIN"]

# PNG value = GAIN x radiance x 65535: the satin relief's brightest value under 60 dome lights,
# 0.26 at 1 % noise (a 6000 x 31 band), maps to 0.78 of the range (nothing clipped)
GAIN = 3.0


def write_dome_capture(folder, w, h, m, material, compression=0, cast_shadows=True):
    """The relief at w x h px under m dome lights as a DiLiGenT folder, band by band (the bands of
    `--banded`), with its cast shadows (`lights.render_band`) unless not `cast_shadows`; PNGs stored
    uncompressed by default (zlib level `compression`): the input's writing is the bench's cost, not
    the product's. Prints {"render_cpu_s", "write_cpu_s", "hidden_of_lit"} as JSON (the share of the
    lit samples, s.n > 0, that the relief hides, cast or not)."""
    from facette.bench.lights import band_rows, dome_lights, relief_heights, render_band
    from facette.bench._render_jit import cast_hidden
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    lights = dome_lights(m)
    names = [f"{i + 1:03d}.png" for i in range(m)]
    (folder / "filenames.txt").write_text("\n".join(names) + "\n")
    np.savetxt(folder / "light_directions.txt", lights, fmt="%.8f")
    np.savetxt(folder / "light_intensities.txt", np.full((m, 3), GAIN), fmt="%.8f")
    writers = [PngBandWriter(folder / name, w, h, 3, np.uint16, compression) for name in names]
    truth = open(folder / "normal_gt.npy", "wb")
    np.lib.format.write_array_header_1_0(truth, {"descr": "<f4", "fortran_order": False, "shape": (h, w, 3)})
    rows, render_c, write_c = band_rows(w, m), 0.0, 0.0
    c = time.process_time()
    heights = relief_heights(h, w)
    render_c += time.process_time() - c
    lit = hidden = 0
    try:
        for r0 in range(0, h, rows):
            c = time.process_time()
            r1 = min(h, r0 + rows)
            cast = cast_hidden(heights, r0, r1, lights)
            images, normals = render_band(r0, r1, w, min(h, w), lights, material, hidden=cast if cast_shadows else None)
            band_lit = np.einsum("rwd,md->mrw", normals, lights) > 0
            lit, hidden = lit + int(band_lit.sum()), hidden + int((band_lit & cast).sum())
            render_c += time.process_time() - c
            c = time.process_time()
            truth.write(normals.astype("<f4").tobytes())
            for writer, image in zip(writers, images):
                writer.write(np.clip(np.rint(image * (GAIN * 65535)), 0, 65535).astype(np.uint16))
            write_c += time.process_time() - c
        for writer in writers:
            writer.close()
    finally:
        truth.close()
    with PngBandWriter(folder / "mask.png", w, h, 1, np.uint8, 1) as mask:    # last: the folder is complete
        for r0 in range(0, h, rows):
            mask.write(np.full((min(h, r0 + rows) - r0, w), 255, np.uint8))
    print(json.dumps({"render_cpu_s": render_c, "write_cpu_s": write_c, "hidden_of_lit": hidden / max(lit, 1)}))


def measure_capture(w, h, m, material, work, outputs="normals,height", cast_shadows=True):
    """The capture written when missing (its rendering's CPU s and the share of the lit samples the relief
    hides said), then `facette process` on it with no flag but --outputs: wall and CPU s (every thread),
    per MP-light, the peak (max RSS), the stage times, the error to the truth, the share of the lit
    samples the cast-shadow step found hidden (process.json), the method and budget notes and the 1-minute
    load before and after. A capture without its cast shadows (`cast_shadows` False) is a folder of its own."""
    from facette.bench import size
    from facette.bench.e2e import _times
    work = Path(work)
    tag = f"{w}x{h}x{m}_{material}{'_cast' if cast_shadows else ''}"
    folder = work / f"dome_{tag}"
    if not (folder / "mask.png").is_file():
        cmd = [sys.executable, "-m", "facette.bench.lights", "--_write", folder, w, h, m, material, int(cast_shadows)]
        stdout, wall, gb = size._run_rss(size._measured(cmd))
        info = json.loads(stdout.strip().splitlines()[-1])
        print(f"capture {w}x{h} x {m} lights written in {wall:.1f} s ({size.LAST_CPU[0]:.1f} CPU s: rendering "
              f"{info['render_cpu_s']:.1f}, PNGs {info['write_cpu_s']:.1f}), peak {gb:.2f} GB; the relief hides "
              f"{info['hidden_of_lit']:.2%} of the lit samples ({'cast' if cast_shadows else 'not cast'})", flush=True)
    out = work / f"dome_out_{tag}"
    load0 = os.getloadavg()[0]
    stdout, wall, gb = size._run_rss(size._measured(size.FACETTE + ["process", folder, "-o", out, "--outputs",
                                                                    outputs, "--overwrite"]))
    cpu, load1, mpl = size.LAST_CPU[0], os.getloadavg()[0], w * h * m / 1e6
    times = ", ".join(f"{k} {v:.1f}" for k, v in _times(stdout).items())
    notes = [line.strip() for line in stdout.splitlines() if "note:" in line]
    err = size._truth_error(folder, out / "normal.exr")
    shadows = json.loads((out / "process.json").read_text()).get("quality", {}).get("shadows", {})
    print(f"process {w}x{h} x {m} lights, no flag (--outputs {outputs}): {wall:.1f} s wall, {cpu:.1f} CPU s "
          f"({cpu / mpl:.3f} CPU s/MP-light; {cpu / 2:.0f} s on two busy cores), peak {gb:.2f} GB, {err:.3f}° to the "
          f"truth, the shadow step's hidden share {shadows.get('hidden_share')}; load {load0:.1f} -> {load1:.1f}\n  {stdout.splitlines()[0].strip()}\n  times: {times}", flush=True)
    for note in notes:
        print(f"  {note}")
