"""`bench relight --large`'s child: its resident memory and the temporary disk it holds, sampled per
stage of `process` while it runs (`StageSampler`), so that a run stopped before its end still gives
its figures (each sample is written to a log as it is taken).

The stages are `pipeline._process`'s functions, wrapped while the sampler runs: the load and photometric
stereo (whole or over bands), the normals' uncertainty, the heights, the relighting model, the last
files. The disk counted: the files under the temporary folder and the results folder, and those this
process holds open or mapped there without a name (`_memory.disk_array`'s, deleted at creation).
"""
import os
import threading
import time

__all__ = ["StageSampler", "STAGES"]

# pipeline._process's functions a stage is named after while it runs
# (names `process` no longer has are skipped: "solved" is the band loop, whole or over bands, since one-band)
STAGES = (("whole_process", "load+ps whole"), ("banded_process", "load+ps bands"), ("solved", "load+ps"),
          ("uncertainty_of", "uncertainty"), ("integrate", "heights"), ("relight_model_stage", "relight model"),
          ("_write_last", "last files"))


def resident_bytes():
    with open("/proc/self/status") as fh:
        for line in fh:
            if line.startswith("VmRSS:"):
                return int(line.split()[1]) * 1024
    return 0


def held_disk(roots):
    """Bytes of the files under `roots` (folders) and of those this process holds open or mapped there
    (named or deleted), each file once."""
    seen, total = set(), 0

    def add(st):
        nonlocal total
        if (st.st_dev, st.st_ino) not in seen:
            seen.add((st.st_dev, st.st_ino))
            total += st.st_blocks * 512
    for folder in ("/proc/self/fd", "/proc/self/map_files"):
        try:
            names = os.listdir(folder)
        except OSError:
            continue
        for name in names:
            try:
                if os.readlink(f"{folder}/{name}").startswith(tuple(roots)):
                    add(os.stat(f"{folder}/{name}"))
            except OSError:
                pass
    for root in roots:
        for dirpath, _, files in os.walk(root):
            for f in files:
                try:
                    add(os.stat(os.path.join(dirpath, f)))
                except OSError:
                    pass
    return total


class StageSampler:
    """Peak resident memory and held disk per stage of process (`peaks`, `disk`: {stage: bytes}),
    sampled every `every` s on a thread while `with` holds; each sample appended to `log` (a path)."""

    def __init__(self, roots, log, every=1.0, disk_every=4):
        self.roots, self.log, self.every, self.disk_every = [str(r) for r in roots], log, every, disk_every
        self.stage, self.peaks, self.disk, self._stop = "other", {}, {}, threading.Event()
        self._saved = []

    def __enter__(self):
        import facette.pipeline._process as process_module
        for name, label in STAGES:
            fn = getattr(process_module, name, None)
            if fn is None:
                continue
            self._saved.append((process_module, name, fn))
            setattr(process_module, name, self._wrapped(fn, label))
        self.t0 = time.perf_counter()
        self._thread = threading.Thread(target=self._run, daemon=True)
        self._thread.start()
        return self

    def __exit__(self, *exc):
        self._stop.set()
        self._thread.join()
        for module, name, fn in self._saved:
            setattr(module, name, fn)

    def _wrapped(self, fn, label):
        def run(*args, **kwargs):       # sampled on entry and on exit too: a short stage is counted
            before, self.stage = self.stage, label
            self._sample(label, True)
            try:
                return fn(*args, **kwargs)
            finally:
                self._sample(label, True)
                self.stage = before
        return run

    def _sample(self, stage, disk):
        rss = resident_bytes()
        self.peaks[stage] = max(self.peaks.get(stage, 0), rss)
        held = held_disk(self.roots) if disk else None
        if held is not None:
            self.disk[stage] = max(self.disk.get(stage, 0), held)
        return rss, held

    def _run(self):
        k = 0
        with open(self.log, "a") as log:
            while not self._stop.is_set():
                stage = self.stage
                rss, disk = self._sample(stage, k % self.disk_every == 0)
                log.write(f"{time.perf_counter() - self.t0:.0f} s {stage}: {rss / 1e9:.2f} GB"
                          + ("" if disk is None else f", disk {disk / 1e9:.2f} GB") + "\n")
                log.flush()
                k += 1
                self._stop.wait(self.every)

    def summary(self):
        """'stage peak GB (disk GB), ...' in the order the stages came."""
        return ", ".join(f"{s} {p / 1e9:.2f} GB" + (f" (disk {self.disk[s] / 1e9:.1f} GB)" if s in self.disk else "")
                         for s, p in self.peaks.items())
