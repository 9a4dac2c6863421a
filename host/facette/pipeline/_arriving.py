"""The one-button scan's photographs made into `process`'s inputs as they arrive, before the last frame.

A scan with `hold_hdr` merges each light on a worker as soon as its frames have landed and holds it in
memory; `ArrivingLights` (the scan's `ScanOptions.on_held`) then takes each held light on a thread of
its own and does there what `process` would do to it after the last frame:

- `capture.scan.load_scan`'s part for one light: its radiance into the stack, NaN where its variance is
  not finite, its usable samples (green SNR), divided by the light's intensity and the flat field;
- the solve's fourth channel (`_channels.with_solve_channel`: the mean of R, G, B, `process`'s default
  channels) of that light, into the solve's stack.

`load_scan(..., prepared=)` takes the stack when every light of the scan came, unchanged on disk, with
the same lights, intensities and profile it would use (`stacks`); else it reads as before. `HeldBands`
(pipeline._whole) takes the solve's stack when its weights and saturation are the ones used here
(`solve_stack`). The same values either way, in the same order of operations (float32); the work is done
on the light's arrival, beside the scan: at 4288x2848 and 12 lights the load after the last frame drops
from ~1.1 to ~0.6 CPU s (the object's masks remain: they need every light) and the solve's channel
(0.4-1.6 CPU s, most of it the first touch of a 590 MB array) leaves it. Memory: the stacks (440 MB +
590 MB at that size) replace the held lights (600 MB) during the scan.
"""
from concurrent.futures import ThreadPoolExecutor

import numpy as np

from facette.capture.scan import divide_intensities, merged_lights, profile_flat, scan_lights
from facette.capture.usable import usable_from_green
from facette.pipeline._channels import CHANNELS_DEFAULT

__all__ = ["ArrivingLights"]


class ArrivingLights:
    """`ScanOptions.on_held` of a scan processed right after it: each held light made into the stack
    `load_scan` would read (and the solve's channel appended, `solve_channel`: the mean of R, G, B) on a
    thread of its own. saturation: `ProcessOptions.saturation` the solve's channel is made with."""

    def __init__(self, solve_channel=CHANNELS_DEFAULT == "mean", saturation=None):
        self.weights = np.full(3, 1 / 3, np.float32) if solve_channel else None   # _channels.channel_weights' mean
        self.saturation = saturation
        self.pool = ThreadPoolExecutor(1, thread_name_prefix="arriving")
        self.futures, self.held = [], {}
        self.images = self.usable = self.solve = self.stack = None
        self.failed = None                       # why the stack cannot be used (then `stacks` gives None)

    def __call__(self, sd, light):
        """A light held by the scan directory `sd`: made into the stack on the worker."""
        sd.prepared = self
        self.futures.append(self.pool.submit(self._add, sd, int(light)))

    def _setup(self, sd, shape):
        data = sd.manifest
        self.ids = sorted(int(l.index) for l in data.lights)
        by_index = {int(l.index): l for l in data.lights}
        self.inten = scan_lights(sd.path, data, [by_index[i] for i in self.ids])[1]
        self.profile = (data.profile, shape)
        pitch, notes, flat = profile_flat(data, sd.path, shape[::-1])
        if flat is not None and (flat.shape != shape + (3,) or not np.all(np.isfinite(flat)) or np.any(flat <= 0)):
            raise ValueError("the flat field does not fit the images")     # load_scan says it, reading whole
        self.flat, self.profile_out = flat, (pitch, notes)
        m, (h, w) = len(self.ids), shape
        self.images = np.empty((m, h, w, 3), np.float32)
        self.usable = np.empty((m, h, w), bool)
        self.solve = None if self.weights is None else np.empty((m, h, w, 4), np.float32)

    def _add(self, sd, light):
        held = sd.take_held(light)
        arrays = None if held is None else held.arrays()
        try:
            if self.failed is not None:
                return
            if arrays is None:
                raise ValueError(f"light {light} changed on disk since it was merged")
            radiance, v_green = arrays
            if self.images is None:
                self._setup(sd, v_green.shape)
            k = self.ids.index(light)
            if radiance.shape != self.images.shape[1:]:
                raise ValueError(f"light {light} is {radiance.shape}, not {self.images.shape[1:]}")
            self._light(k, radiance, v_green)
            self.held[light] = held
        except Exception as exc:       # the stack is not used; load_scan reads the files and says what is wrong
            self.failed = f"{type(exc).__name__}: {exc}"
        finally:
            if held is not None:
                held.release()

    def _light(self, k, radiance, v_green):
        """Light k as `load_scan` makes it (capture.scan: `_read_hdr_fast`'s held light, the intensity's
        division of its rows, `_apply_profile`), and its solve's channel (`_channels.with_solve_channel`)."""
        img = self.images[k]
        img[...] = radiance
        img[np.isnan(v_green)] = np.nan
        self.usable[k] = usable_from_green(img[..., 1], v_green)
        divide_intensities(self.images[k:k + 1], self.inten[k:k + 1])
        if self.flat is not None:
            np.divide(img, self.flat, out=img)
        if self.solve is not None:
            from facette.pipeline._pixels_jit import append_weighted     # numba: loaded on first use
            append_weighted(self.images, self.weights, self.saturation, self.solve, slice(k, k + 1))

    def stacks(self, scan_dir, data):
        """`load_scan`'s (images, usable, lights, HDR notes, (pixel pitch, profile notes)) made as the lights
        arrived, when every light of `data` came unchanged with the same intensities and profile; else None
        (the stack dropped: load_scan reads)."""
        self.wait()
        ok = self.failed is None and self.images is not None
        if ok:
            ids, lights, notes = merged_lights(scan_dir, data)        # as load_scan checks them
            ok = (not notes and ids == self.ids and set(self.held) == set(ids)
                  and all(h.unchanged() for h in self.held.values()) and self.profile == (data.profile, self.images.shape[1:3])
                  and np.array_equal(scan_lights(scan_dir, data, lights)[1], self.inten))
        if not ok:
            self.images = self.usable = self.solve = None
            return None
        images, usable = self.images, self.usable
        self.images = self.usable = None
        self.stack = images                     # what `solve_stack` checks it is asked about
        return images, usable, lights, notes, self.profile_out

    def solve_stack(self, images, weights, saturation):
        """The solve's stack (m, H, W, 4) of `images` (this object's stack) for these weights and saturation,
        or None; it leaves this object."""
        solve, self.solve = self.solve, None
        if solve is None or images is not self.stack or weights is None \
                or not np.array_equal(weights, self.weights) or saturation != self.saturation:
            return None
        return solve

    def wait(self):
        for f in self.futures:
            f.result()

    def close(self):
        """Stop the worker and drop the stacks."""
        self.pool.shutdown(wait=True)
        self.images = self.usable = self.solve = self.stack = None
