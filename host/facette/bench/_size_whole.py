"""`facette bench size --only-no-flag --against-whole`: the no-flag run's normals and heights against
the same capture read whole (issue 49 asks <= 0.01 deg at 12 MP).

The no-flag run reads the capture band by band when its whole reading (`pipeline._budget.whole_bytes`)
exceeds the default budget (half the free memory less 1 GB: at 12 MP x 12 lights ~10.1 GB against
~9.7 GB on a machine with 21.3 GB free). Without a flag, whether a run is read whole depends on the
free memory of the moment; so the reference is `facette process SRC --memory X` with X the least
budget (whole GB) with which `process` reads it whole, as its one band (`_streamed.read_in_bands`;
checked on its note): the same files as a run without --memory that fits. At 12 MP that budget is
19 GB though the reading holds ~10 GB (the band's rows are sized for more: with 12 GB, two bands).
Printed: wall and CPU s, peak, and the normals' largest and mean angle between the runs, the pixels
over 0.01 deg, and the largest height difference over the whole run's height range.
"""
import os
import re
from pathlib import Path

import numpy as np

from facette.io.exr import read_exr

__all__ = ["whole_memory", "against_whole", "normals_apart"]

AGREE_DEG = 0.01
BAND_ROWS = 256


def whole_memory(source, outputs=("normals", "height")):
    """The least --memory in whole GB (e.g. "20GB") in which `process` reads `source` whole, as its one
    band (`_streamed.read_in_bands`: the whole reading's figure must fit, 10.1 GB at 12 MP x 12 lights;
    until this stop the band's rows had to fit too, 20 GB)."""
    from facette.pipeline._options import ProcessOptions
    from facette.pipeline._streamed import read_in_bands
    total = os.sysconf("SC_PHYS_PAGES") * os.sysconf("SC_PAGE_SIZE")
    for gb in range(1, int(total // 10 ** 9) + 1):
        if not read_in_bands(source, ProcessOptions(memory=f"{gb}GB"), list(outputs)):
            return f"{gb}GB"
    raise SystemExit(f"{source}: no budget within this machine's {total / 1e9:.1f} GB reads it whole")


def _angles_deg(a, b):
    a, b = a.astype(np.float64), b.astype(np.float64)
    return np.degrees(np.arctan2(np.linalg.norm(np.cross(a, b), axis=-1), np.sum(a * b, axis=-1)))


def normals_apart(whole_dir, other_dir):
    """(largest angle deg, mean angle deg, pixels over AGREE_DEG, pixels compared, largest height
    difference / the whole run's height range) where the whole run has a normal."""
    xyz = ("X", "Y", "Z")
    a, b = read_exr(Path(whole_dir) / "normal.exr", xyz)[0], read_exr(Path(other_dir) / "normal.exr", xyz)[0]
    mask = np.linalg.norm(a, axis=-1) > 0.5
    worst, total, over = 0.0, 0.0, 0
    for r0 in range(0, mask.shape[0], BAND_ROWS):
        sl = slice(r0, r0 + BAND_ROWS)
        apart = _angles_deg(a[sl][mask[sl]], b[sl][mask[sl]])
        worst, total = max(worst, float(apart.max(initial=0.0))), total + float(apart.sum())
        over += int((apart > AGREE_DEG).sum())
    del a, b
    ha, hb = (read_exr(Path(d) / "height.exr")[0][..., 0] for d in (whole_dir, other_dir))
    span = float(np.ptp(ha[mask])) if mask.any() else 0.0
    height = float(np.abs(ha - hb)[mask].max(initial=0.0)) / span if span > 0 else float("nan")
    count = int(mask.sum())
    return worst, total / max(count, 1), over, count, height


def against_whole(source, noflag_dir, out_dir, run):
    """`process SOURCE --memory whole_memory(SOURCE)` (run: bench size's measured runner, returning
    (stdout, wall s, peak GB, CPU s)), checked read whole, then compared with the no-flag results."""
    from facette.bench.size import FACETTE
    memory = whole_memory(source)
    stdout, wall, gb, cpu = run(FACETTE + ["process", source, "-o", out_dir, "--outputs", "normals,height",
                                           "--memory", memory, "--overwrite"])
    one = re.search(r"over 1 band of \d+ rows: the capture fits one band, read whole", stdout)
    method = re.search(r"\((\w+)\)\s*$", stdout.splitlines()[0])
    worst, mean, over, count, height = normals_apart(out_dir, noflag_dir)
    print(f"read whole (--memory {memory}{'' if one else ': NOT read whole, see its notes'}): {wall:.1f} s, "
          f"{cpu:.1f} CPU s, peak {gb:.2f} GB, {method.group(1) if method else '?'}; no flag against it: normals "
          f"max {worst:.5f}°, mean {mean:.6f}°, {over} of {count} px over {AGREE_DEG}°; heights max "
          f"{height:.2e} of the range", flush=True)
    if not one:
        print("\n".join(line for line in stdout.splitlines() if "note:" in line or "--memory" in line))
    return worst, mean, over, height
