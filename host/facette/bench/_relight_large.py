"""`facette bench relight --large WxH`: the relighting model on a large generated capture.

A relief slab (`bench._large.write_relief_capture`: 12 lights, 16-bit PNGs, written band by
band) goes through `process(folder, outputs=["relight"])` in a process of its own, as
`facette process SLAB -o OUT --outputs relight` runs it; printed: the whole run's wall and CPU
time, the model stage's (`res.timings["relight_model"]`) in s/MP, the planes kept, relight_model.npz's
size, the child's peak memory (its max RSS, from wait4) and, sampled while it runs
(`_relight_sampler.StageSampler`), the peak memory and temporary disk of each stage (its temporary
folder is one of its own: TMPDIR). `free`: the free memory the child's default budget is told of (as a
machine with that much decides: 64e9 on a 12 MP capture reads it whole unless the relighting budget
sends it over bands); the samples go to `large_samples.txt` as they come (a run stopped early still
gives them).
"""
import os
import shutil
import subprocess
import sys
import time
from pathlib import Path

__all__ = ["run_large"]

CHILD = [sys.executable, "-m", "facette.bench._relight_large"]


def run_large(size, work, method="woodham1980", memory=None, free=None, outputs="relight", capture=None):
    """Generate the slab (w, h) in `work` (or take the slab folder `capture`), run process on it in a child
    process, print its figures."""
    from facette.bench._large import write_relief_capture
    w, h = size
    folder = Path(capture) if capture else Path(work) / f"slab_{w}x{h}"
    if not capture:
        t0 = time.perf_counter()
        write_relief_capture(folder, w, h)
        print(f"large: {w}x{h} slab ({w * h / 1e6:.1f} MP, 12 lights) written in {time.perf_counter() - t0:.0f} s",
              flush=True)
    t0 = time.perf_counter()
    log, tmp = Path(work) / "large_child.txt", Path(work) / "large_tmp"
    tmp.mkdir(parents=True, exist_ok=True)
    args = [str(folder), str(Path(work) / "out_large"), method, str(memory), str(free), outputs,
            str(Path(work) / "large_samples.txt")]
    try:
        with open(log, "w") as fh:
            proc = subprocess.Popen(CHILD + args, stdout=fh, env=dict(os.environ, TMPDIR=str(tmp)))
            _, status, usage = os.wait4(proc.pid, 0)
            proc.returncode = os.waitstatus_to_exitcode(status)     # reaped here: Popen must not wait again
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    out = log.read_text()
    wall = time.perf_counter() - t0
    if proc.returncode:
        print(f"large: process failed ({proc.returncode})")
        return
    told = "" if free is None else f", told of {float(free) / 1e9:.0f} GB free"
    print(f"large: process --outputs {outputs} ({method}, --memory {memory}{told}) {wall:.0f} s wall, "
          f"{usage.ru_utime + usage.ru_stime:.0f} CPU s, peak {usage.ru_maxrss / 1e6:.2f} GB; "
          + out.strip(), flush=True)


def _child(folder, out, method, memory, free, outputs, samples):
    from facette.bench._relight_sampler import StageSampler
    from facette.pipeline import ALL_OUTPUTS, _budget, process
    if free != "None":
        _budget.free_memory = lambda: int(float(free))
    with StageSampler([os.environ.get("TMPDIR", "/tmp"), out], samples) as sampler:
        res = process(folder, outputs=list(ALL_OUTPUTS) if outputs == "all" else outputs.split(","), out_dir=out,
                      method=method, **({} if memory == "None" else {"memory": memory}))
    read = next((n.split(": ", 1)[1] for n in res.notes if n.startswith("memory: ")), "the whole reading")
    print(f"read: {read}")
    print(f"per stage: {sampler.summary()}")
    if res.relight_model is None:
        return
    mpx = res.relight_model.mask.sum() / 1e6
    k = 0 if res.relight_model.planes is None else res.relight_model.planes.shape[-1]
    size = os.path.getsize(Path(out) / "relight_model.npz") / 1e6
    print(f"model stage {res.timings['relight_model']:.0f} s ({res.timings['relight_model'] / mpx:.1f} s/MP, "
          f"{mpx:.1f} MP fitted), {k} planes, relight_model.npz {size:.0f} MB "
          f"({size / mpx:.0f} B/px), mean ρ {_mean(res.relight_model.rho):.3f}")


def _mean(a, rows=256):
    """The mean of `a`, read `rows` rows at a time (a spilled model's pages handed back: not read whole
    into this process's peak)."""
    import numpy as np
    from facette._memory import release
    total = 0.0
    for r0 in range(0, len(a), rows):
        total += float(np.sum(a[r0:r0 + rows], dtype=np.float64))
        release(a)
    return total / max(a.size, 1)


if __name__ == "__main__":
    _child(*sys.argv[1:8])
