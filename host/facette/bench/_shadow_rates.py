"""`facette bench lights --shadow-rates WxH`: the cast-shadow step's hidden lights against the geometry's.

The step (pipeline._shadows: robust passes on binned images, heights integrated from their normals, a
horizon test SHADOW_MARGIN_DEG soft) runs on images held whole, at each margin given; the truth is the
lights the true heights hide (`_render_jit.cast_hidden`, a march of its own). Per scene and margin, over
the lit samples (s.n > 0 at the true normal, on the mask): the share the geometry hides, the share the
step found hidden, its hit rate (of the truly hidden, the share found) and its false-hidden share (lit
samples found hidden that are not, a good sample thrown away).

Scenes: the relief of `--capture` (slopes up to 49 deg; 60 dome lights at 10-80 deg; Cook-Torrance satin, 1 %
noise) at WxH with its cast shadows and without (as `--capture` rendered it before December 2026: its
hidden values lit); at 1500x1000 the step's alternation runs on 750 x 500 bins, as on 24 MP. With
--concave-cache DIR, also bench concave's path-traced concave scenes under its 96 lights (paint_0.10;
rendered by Mitsuba into DIR when missing: minutes each).
"""
import time
from types import SimpleNamespace

import numpy as np

from facette.pipeline._shadows import alternation_bin, binned_pass, decision_bin, hidden_of_bins, upsampled

from ._render_jit import cast_hidden

__all__ = ["found_hidden", "rates", "shadow_rates_main"]


def found_hidden(images, light_dirs, mask, margin_deg):
    """(m, H, W) bool: the lights the cast-shadow step finds hidden on `images` held whole (as
    `process` with --shadows on: the decision's bins, the alternation's, upsampled to the mask)."""
    res = SimpleNamespace(quality={}, timings={}, notes=[])
    f, fa = decision_bin(mask), alternation_bin(mask)
    decision = binned_pass(images, light_dirs, mask, mask, f)
    hidden, fa = hidden_of_bins(res, SimpleNamespace(shadows="on"), decision,
                                lambda: decision if fa == f else binned_pass(images, light_dirs, mask, mask, fa),
                                "li_alternating", {}, margin_deg=margin_deg)
    return upsampled(hidden, fa, mask)


def rates(found, truth, normals, light_dirs, mask):
    """(truly hidden share, found share, hit rate, false-hidden share) over the lit samples."""
    lit = (np.einsum("hwd,md->mhw", np.asarray(normals, np.float32), np.asarray(light_dirs, np.float32)) > 0) & mask
    n = max(int(lit.sum()), 1)
    hidden = truth & lit
    return (hidden.sum() / n, (found & lit).sum() / n, (found & hidden).sum() / max(int(hidden.sum()), 1),
            (found & ~truth & lit).sum() / n)


def _relief(w, h, cast):
    from .lights import dome_lights, relief_heights, render_band
    lights = dome_lights(60)
    truth = cast_hidden(relief_heights(h, w), 0, h, lights)
    images, normals = render_band(0, h, w, min(h, w), lights, "satin", hidden=truth if cast else None)
    return images, lights, np.ones((h, w), bool), normals, truth


def _concave(shape, cache):
    from ._mitsuba_scenes import _concave as heights_of
    from .concave import scene
    d = scene(shape, "paint_0.10", "96", cache)
    n = d["mask"].shape[0]
    c = -1 + (np.arange(n) + 0.5) * 2 / n            # pixel centres over [-1, 1], rows down as y runs up
    xx, yy = np.meshgrid(c, -c)
    truth = cast_hidden(heights_of(shape, xx, yy) * n / 2, 0, n, d["light_dirs"])
    return d["images"].astype(np.float32), d["light_dirs"], d["mask"].astype(bool), d["normals"], truth


def shadow_rates_main(w, h, margins, concave_cache=None, shapes=("bowl", "grooves", "craters", "cup")):
    print("-- the cast-shadow step's hidden lights against the geometry's, per margin (deg); shares of the lit "
          "samples; hit: of the truly hidden, the share found")
    print(f"{'scene':34s} {'margin':>6s} {'hidden':>7s} {'found':>7s} {'hit':>6s} {'false-hidden':>12s} {'CPU s':>6s}")
    scenes = [(f"relief {w}x{h}, cast shadows", lambda: _relief(w, h, True)),
              (f"relief {w}x{h}, none cast", lambda: _relief(w, h, False))]
    if concave_cache:
        scenes += [(f"{shape}/paint_0.10/96", lambda shape=shape: _concave(shape, concave_cache)) for shape in shapes]
    for label, make in scenes:
        images, lights, mask, normals, truth = make()
        for margin in margins:
            c = time.process_time()
            found = found_hidden(images, lights, mask, margin)
            share, found_share, hit, false = rates(found, truth, normals, lights, mask)
            print(f"{label:34s} {margin:6.2f} {share:7.2%} {found_share:7.2%} {hit:6.1%} {false:12.2%} "
                  f"{time.process_time() - c:6.1f}", flush=True)
