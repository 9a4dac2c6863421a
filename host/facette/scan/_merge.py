"""The HDR merge during acquisition: each light merged on a worker (`LightMerger`) as soon as
its frames have landed, the finished merges recorded in scan.json's "hdr" and, when held, kept
in the scan directory object for the processing that follows in this process."""
from __future__ import annotations

from facette.scan.hdr import LightMerger, scan_sensor, store_light_records

__all__ = ["MergeDuringScan"]


class MergeDuringScan:
    """Merges the lights of scan directory `sd` while it is acquired (`n_exposures` per light);
    `hold`: keep each merged light in memory (`ScanDirectory.hold_light`); `on_held`: called with (sd, light)
    as each is held (`ScanOptions.on_held`)."""

    def __init__(self, sd, n_exposures, hold=False, on_held=None):
        self.sd, self.n_exposures, self.on_held = sd, n_exposures, on_held
        self.merger = LightMerger(sd.path, hold=hold)

    def _complete(self, light, done):
        return all((light, e) in done for e in range(self.n_exposures))

    def submit_stale(self, n_lights):
        """A resumed scan: queue the lights complete but not merged yet (or whose frames changed)."""
        done = self.sd.frames_done()
        for light in range(n_lights):
            if self._complete(light, done) and self.merger.stale(self.sd.manifest, light):
                self.merger.submit(self.sd.manifest, light)

    def frame_landed(self, light):
        """Queue a light's HDR merge once all its exposures have landed (and been hashed);
        store the merges that finished meanwhile."""
        if self._complete(light, self.sd.frames_done()):
            self.merger.submit(self.sd.manifest, light)
        self.store(wait=False)

    def store(self, wait=False):
        """Record the finished merges in scan.json (`wait`: for every queued one); a held light
        goes to the scan directory object, for the processing that follows in this process."""
        finished = self.merger.collect(wait=wait)
        records = []
        for light, rec, held in finished:
            if isinstance(rec, Exception):
                self.sd.journal("hdr_error", light=light, error=f"{type(rec).__name__}: {rec}"[:300])
            else:
                records.append(rec)
                self.sd.journal("hdr_light", light=light, time_s=rec.time_s)
                if held is not None:
                    self.sd.hold_light(light, held)
                    if self.on_held is not None:
                        self.on_held(self.sd, light)
        if records:
            m = self.sd.manifest
            _, source = scan_sensor(m, self.merger.sensor)
            m.set_hdr(store_light_records(m, records, self.merger.basis(m), source))
            self.sd.save()

    def close(self):
        """Store the last merges (an interrupted scan keeps the rest) and stop the worker."""
        try:
            self.store(wait=True)
        finally:
            self.merger.close()
