"""`facette bench uncertainty`: does each normal's uncertainty (normal.exr's uncertainty_deg) rank
the true errors, and does its 90 % band hold 90 % of the normals?

Per case: Spearman's rank correlation between the uncertainty and the angular error against the
truth, the share of pixels whose error is within the band (coverage; the aim: 0.9), before (the
local fit's band alone, BAND_SCALE u) and after (with the normal field's curl, K_CURL), the medians
of the band and of the error, and the seconds the uncertainty took (and per megapixel of image).
Four sources:
- synthetic renders (facette.recon.synthetic: a sphere on a plane, cast shadows, matte, satin
  and glossy Cook-Torrance, noise 0.5 % and 2 %, the rig's 12 lights and 40 lights over the
  upper hemisphere): made here in seconds;
- Mitsuba 3 renders (path-traced: inter-reflections, a relief, a vase), unless --no-mitsuba;
- the path-traced concave scenes of `facette bench concave` (bowl, grooves, craters, cup; plaster
  and paint; 12 rig lights and 96) through `facette process`, unless --no-concave (rendering the
  ones not cached takes minutes each);
- DiLiGenT with truth (`facette bench diligent`'s folders, through `facette process`), unless --no-real.
The renders choose BAND_SCALE and K_CURL (the line "pooled over the renders" prints the scale
that would put 90 % of their normals inside the band); DiLiGenT only confirms them.
Each case also prints how rankable its errors are: their 10th-90th percentile (an error that is about the
same everywhere, as the 16-bit ball's ~2 deg, has no order for any measure to find). --candidates adds a line
per case with the Spearman of the measures tried and not taken (bench._uncertainty_candidates: a
leave-one-light-out jackknife, the kept lights' count, conditioning and spread, residuals; and, from the
solve's own model, bench._uncertainty_li: the LI model's Laplace covariance, its bound, two half-light solves; the
non-local ones of bench._uncertainty_global: the angle to the whole field's least-squares surface, the sky and the
lights that surface hides; the re-solves of bench._uncertainty_bootstrap and _uncertainty_selfcal: a residual
bootstrap through the default's per-pixel solve, the cost's other valleys, a sector jackknife, the lights'
calibration error as all the pixels show it).
Each group ends with its mean over the cases (the bar is read on it) and the Spearman and coverage of all its
pixels pooled. --combination fits a combination of the measures on the renders' ranks
(bench._uncertainty_combination) and prints its Spearman per case, DiLiGenT only scored; then, as a bound never
used for the map, the same combination fitted on the other DiLiGenT objects (leave one out) and on each itself.
"""
import argparse
import time

import numpy as np
from scipy.stats import spearmanr

from facette.bench.diligent import angular_errors, default_root, find_objects, object_name
from facette.methods import photometric_stereo
from facette.recon import normal_uncertainty
from facette.recon import _uncertainty as unc
from facette.recon.synthetic import render, sphere_on_plane, thesis_light_directions

MITSUBA_SCENES = (("sphere", "paint_0.10"), ("relief", "plaster"), ("relief", "paint_0.05"), ("vase", "satin"))


def hemisphere_lights(n=40, min_z=0.4, seed=3):
    """n unit directions spread at random over the upper hemisphere above elevation asin(min_z)."""
    rng = np.random.default_rng(seed)
    v = rng.normal(size=(20 * n, 3))
    v[:, 2] = np.abs(v[:, 2])
    v /= np.linalg.norm(v, axis=1, keepdims=True)
    return v[v[:, 2] > min_z][:n]


def synthetic_cases(size=64):
    """(name, images, light_dirs, truth normals, mask) of the synthetic renders."""
    for lights, lname in ((thesis_light_directions(), "12 rig lights"), (hemisphere_lights(), "40 lights")):
        for mat in ("matte", "satin", "glossy"):
            for noise in (0.005, 0.02):
                sc = sphere_on_plane(size, size)
                im = render(sc, lights, mat, noise=noise, rng=np.random.default_rng(2)).astype(np.float32)
                yield f"sphere/{mat} {lname} noise {noise:.1%}", im, lights, sc.normals, sc.mask


def mitsuba_cases(cache, size, spp):
    from facette.bench._mitsuba_scenes import render_scene
    from scipy.ndimage import binary_erosion
    for shape, mat in MITSUBA_SCENES:
        d = render_scene(shape, mat, size=size, spp=spp, cache_dir=cache)
        yield (f"mitsuba {shape}/{mat} 12 rig lights", d["images"], d["light_dirs"], d["normals"],
               binary_erosion(d["mask"], iterations=1))


def score(u, err):
    """(spearman, coverage, median u, median error) of uncertainties u and errors err (deg)."""
    rho = float(spearmanr(u, err).statistic) if len(u) > 2 else float("nan")
    return rho, float(np.mean(err <= u)), float(np.median(u)), float(np.median(err))


def before_after(u, normals):
    """(before, after) bands (H, W): `after` the map as written, `before` the local fit's band alone
    (the curl term taken out: after² − (K_CURL·curl)², exact below MAX_DEG)."""
    has = np.linalg.norm(normals, axis=-1) > 0.5
    curl = np.degrees(unc.K_CURL * unc.curl_angle(normals, has))
    before = np.where(u < unc.MAX_DEG, np.sqrt(np.maximum(u.astype(np.float64) ** 2 - curl ** 2, 0)), u)
    return before, u


def _line(name, sb, sa, dt, mpix, err):
    p10, p90 = np.percentile(err, [10, 90]) if len(err) else (np.nan, np.nan)
    return (f"{name:40s} | {sb[0]:5.2f} {sb[1]:5.2f} | {sa[0]:5.2f} {sa[1]:5.2f} | {sa[2]:6.2f} | {sa[3]:6.2f} | "
            f"{p10:5.2f}-{p90:5.2f} | {dt:6.2f}s {dt / max(mpix, 1e-9):7.1f} s/MP")


HEAD = (f"{'case':40s} | before: rho   cov | after: rho   cov | u med° | err med° | err p10-p90 | "
        "time (uncertainty), per MP\n"
        "(rho: Spearman of the band against the error; cov: share of errors within the band, aim 0.9)")


def candidates_line(measures, err):
    """The Spearman of each measure tried and not taken (bench._uncertainty_candidates' `candidate_measures`), one
    line."""
    from facette.bench._uncertainty_candidates import measure_spearman
    return "    candidates (rho): " + ", ".join(f"{k} {v:+.2f}" for k, v in measure_spearman(measures, err).items())


class Tally:
    """The rows of one group of cases: per-case (rho, cov) before and after, and the pooled band/errors."""
    def __init__(self, name, candidates=False, combination=False):
        self.name, self.before, self.after, self.u, self.e = name, [], [], [], []
        self.candidates = candidates          # print the candidates' line (--candidates)
        self.combination = combination       # keep each case's measures for the combination (--combination)
        self.cases = []                       # [(name, measures, err)]

    def add(self, name, u, normals, err, sel, dt, data=None):
        """data: a callable giving (images, light_dirs) as the solve saw them, and optionally the solve's
        model (solve_model(ps)), for the candidates' line."""
        b, a = before_after(u, normals)
        sb, sa = score(b[sel], err), score(a[sel], err)
        self.before.append(sb[:2])
        self.after.append(sa[:2])
        self.u.append(a[sel] / unc.BAND_SCALE)
        self.e.append(err)
        print(_line(name, sb, sa, dt, sel.size / 1e6, err), flush=True)
        if (self.candidates or self.combination) and data is not None:
            from facette.bench._uncertainty_candidates import candidate_measures
            from facette.bench._uncertainty_combination import COMBINED
            images, lights, *model = data()
            measures = candidate_measures(images, lights, normals, sel,
                                          model=model[0] if model and self.candidates else None)
            if self.candidates:
                print(candidates_line(measures, err), flush=True)
            if self.combination:
                self.cases.append((name, {k: measures[k] for k in COMBINED}, err))

    def summary(self):
        """The mean over the cases (what the bar is read on), then every pixel of the group pooled (after)."""
        if self.before:
            b, a = np.mean(self.before, axis=0), np.mean(self.after, axis=0)
            print(f"{'mean over ' + self.name:40s} | {b[0]:5.2f} {b[1]:5.2f} | {a[0]:5.2f} {a[1]:5.2f} |", flush=True)
            u, e = np.concatenate(self.u) * unc.BAND_SCALE, np.concatenate(self.e)
            print(f"{'pooled pixels of ' + self.name:40s} |             | {spearmanr(u, e).statistic:5.2f} "
                  f"{np.mean(e <= u):5.2f} | ({e.size} pixels)", flush=True)


def render_table(cases, method, tally):
    """Rows for rendered cases (the method's normals straight from photometric_stereo)."""
    for name, im, lights, truth, mask in cases:
        r = photometric_stereo(im, lights, method=method, options={"mask": mask})
        t = time.perf_counter()
        sel = mask & r.valid & (np.linalg.norm(truth, axis=-1) > 0.5)
        u = normal_uncertainty(im, lights, r.normal, mask & r.valid)
        tally.add(name, u, r.normal, angular_errors(r.normal, truth, sel), sel, time.perf_counter() - t,
                  data=lambda: (im, lights, solve_model(r)))
    tally.summary()


def concave_table(cache, light_sets, materials, tally):
    """The path-traced concave scenes of `facette bench concave`, through `facette process` (its default)."""
    import tempfile
    from scipy.ndimage import binary_erosion
    from facette.bench import concave
    with tempfile.TemporaryDirectory() as work:
        for lights in light_sets:
            for material in materials:
                for shape in concave.CONCAVE_SHAPES:
                    d = concave.scene(shape, material, lights, cache)
                    folder = concave._folder(d, work, f"{shape}_{material}_{lights}")
                    _, _, res = concave.run(folder)
                    sel = binary_erosion(d["mask"], iterations=1) & res.mask
                    err = angular_errors(res.normals, d["normals"], sel)
                    tally.add(f"concave {shape}/{material}/{lights}", res.uncertainty, res.normals, err, sel,
                              res.timings.get("uncertainty", float("nan")),
                              data=lambda: (d["images"], d["light_dirs"], solve_model(res.ps)))
    tally.summary()


def _diligent_images(folder, ps=None):
    from facette.io.diligent import read_diligent
    data = read_diligent(folder)
    return data.images, data.light_dirs, solve_model(ps)


def solve_model(ps):
    """(materials, material map, cast-shadow flags) of a PSResult, for the candidates' LI measures (None
    without a BRDF-aware solve)."""
    if ps is None or getattr(ps, "material", None) is None:
        return None
    return ps.info.get("materials"), ps.material, ps.shadow


def diligent_table(root, tally):
    from facette.pipeline import process
    for folder, truth_path in find_objects(root):
        if truth_path is None:
            continue
        res = process(folder, outputs=["normals"])
        truth = np.load(truth_path)
        good = res.mask & (np.linalg.norm(truth, axis=-1) > 0.5)
        err = angular_errors(res.normals, truth, good)
        name = f"{folder.parent.name}/{object_name(folder)} ({err.mean():.2f}° mean)"
        tally.add(name, res.uncertainty, res.normals, err, good, res.timings.get("uncertainty", float("nan")),
                  data=lambda: _diligent_images(folder, res.ps))
    tally.summary()


def main(argv=None):
    ap = argparse.ArgumentParser(prog="facette bench uncertainty", description=__doc__.splitlines()[0])
    ap.add_argument("--method", default="li_alternating", help="the photometric-stereo method (default: process's)")
    ap.add_argument("--root", default=None, help="folder searched for DiLiGenT-style folders (default ../shared/data)")
    ap.add_argument("--no-real", action="store_true", help="skip DiLiGenT")
    ap.add_argument("--no-mitsuba", action="store_true", help="skip the Mitsuba renders (about 2 min to render once)")
    ap.add_argument("--cache", default="out/mitsuba-cache", help="folder for the cached renders")
    ap.add_argument("--size", type=int, default=96)
    ap.add_argument("--spp", type=int, default=64)
    ap.add_argument("--no-concave", action="store_true", help="skip the concave renders of `facette bench concave`")
    ap.add_argument("--concave-lights", default="rig12,96", help="their light sets (rig12, 96)")
    ap.add_argument("--concave-materials", default="plaster,paint_0.10", help="their materials")
    ap.add_argument("--concave-cache", default="/tmp/facette-concave", help="their cached renders")
    ap.add_argument("--candidates", action="store_true",
                    help="also print each case's Spearman of the measures tried and not taken (a jackknife, ...)")
    ap.add_argument("--combination", action="store_true",
                    help="fit a combination of the measures on the renders, score it on every case (DiLiGenT too)")
    args = ap.parse_args(argv)
    flags = (args.candidates, args.combination)
    print(f"uncertainty of the normals: the 90 % band = sqrt(({unc.BAND_SCALE} u)^2 + ({unc.K_CURL} curl)^2) "
          "(recon._uncertainty); before: the local fit's band alone")
    print(HEAD)
    rendered = [Tally("the synthetic spheres", *flags)]
    render_table(synthetic_cases(), args.method, rendered[0])
    if not args.no_mitsuba:
        rendered.append(Tally("the Mitsuba scenes", *flags))
        render_table(mitsuba_cases(args.cache, args.size, args.spp), args.method, rendered[-1])
    if not args.no_concave:
        rendered.append(Tally("the concave scenes", *flags))
        concave_table(args.concave_cache, args.concave_lights.split(","), args.concave_materials.split(","),
                      rendered[-1])
    u, e = np.concatenate([x for t in rendered for x in t.u]), np.concatenate([x for t in rendered for x in t.e])
    print(f"pooled over the renders: spearman {spearmanr(u, e).statistic:.2f}, coverage "
          f"{np.mean(e <= unc.BAND_SCALE * u):.2f}; the band times "
          f"{np.percentile(e / np.maximum(unc.BAND_SCALE * u, 1e-9), 90):.2f} would hold 90 % of them")
    real = Tally("the DiLiGenT objects", *flags)
    if not args.no_real:
        diligent_table(args.root or default_root(), real)
    if args.combination:
        from facette.bench._uncertainty_combination_table import combination_table
        combination_table(rendered, real)
    return 0
