"""The valid pixels of one `ps_li_alternating` call and the per-pixel steps of its rounds.

`Pixels` holds what the steps read (each valid pixel's values, lights, initial and least-squares
solutions, highlight start) and what they update (normals, K_d, residuals, shadows, which pixels
the BRDF-aware step solved); `Settings` the call's options the steps read. The steps:

- `split_levels`: which pixels need the BRDF-aware step (a light inside the fitted lobe, or a
  highlight); the rest keep the initial solution, or least squares where it explains them,
  corrected for the model's bias (`_lambertian_correction`);
- `refine`: the BRDF-aware per-pixel solve (facette.fit.refine_normals_li) in blocks;
- `choose_model`: round 1's model choice on profile pixels (facette.fit._li_model);
- `lambertian_material`: a material without a lobe;
- `neighbour_round`: a second start from the neighbours' mean where a solved normal stands apart;
- `store`: a solve's results written back.

`Pixels.start`'s highlight test runs compiled, one loop per pixel (`_ps_li_pixels_jit`).
"""
from dataclasses import dataclass

import numpy as np

from facette._threads import run_blocks
from facette.brdf import kappa_from_kd, li_shading_terms
from facette.recon._ps import _ls_normals, _pixel_dirs, _shading
from ._li_model import PROFILE_TABLE_GRID, PROFILE_VALUES, choose_material_model, is_metal
from ._normals_li import CAST_SHADOW_RATIO, RefineResult, refine_normals_li
from ._ps_li_flags import isolated_flags
from ._ps_li_minima import SEARCH_ABOVE_DEG, SEARCH_MAX_LIGHTS, relative_gap, search_pixel_minima

CORRECTION_PASSES = 3       # fixed-point passes of `_lambertian_correction`
LOBE_TAN = 2.5             # a light is inside the lobe when tan θ_h < LOBE_TAN σ (D > 0.2 % of its peak)
ROUND_STEP_TOL = 1e-3      # rad (0.06°): a pixel's solve stops below this step in the rounds too
BLOCK = 32768              # pixels per block of the per-pixel solve (array code, two threads)
BLOCK_COMPILED = 262144    # pixels per call of the compiled solve (it threads inside)
NEIGHBOUR_ROUNDS = 5       # `neighbour_round` repeats while normals move, at most this often
_FIELDS = ("normals", "kd", "used", "rel_residual")


def angle_deg(a, b):
    return np.degrees(np.arccos(np.clip(np.sum(a * b, axis=-1), -1, 1)))


def join_blocks(parts):
    """One RefineResult of the solves of consecutive pixel blocks."""
    return RefineResult(**{k: np.concatenate([getattr(p, k) for p in parts]) for k in _FIELDS})


@dataclass(frozen=True)
class Settings:
    """The options of `ps_li_alternating` that the per-pixel steps read (its docstring)."""
    iterations: int
    fine_iterations: int
    fit_pixels: int
    t_residual: float
    engine: str
    highlight_start: str
    diffuse_models: tuple      # the volume models the model choice tries, the first the default
    neighbour_deg: float = 0.0  # `neighbour_round`'s threshold (0: no neighbour starts)
    minima_search: bool = True  # `neighbour_round` runs `search_minima` first
    isolated_flags: bool = True  # ... and `solve_isolated_flags`


@dataclass
class Pixels:
    """The N valid pixels (flat indices `idx` into H × W) of one call and their state."""
    settings: Settings
    shape: tuple               # (H, W)
    channel: int               # the channel the shadow and highlight tests read
    flat: np.ndarray           # (m, H·W, C) the images
    idx: np.ndarray            # (N,) flat indices of the valid pixels
    s_all: np.ndarray          # (m, 3) or (N, m, 3) light directions
    all_ok: np.ndarray         # (N, m) usable: finite in every channel, unsaturated
    alb: np.ndarray            # (N, C) the initial solution's albedo
    nrm0: np.ndarray           # (N, 3) the initial normals
    nrm_ls: np.ndarray         # (N, 3) least squares over every light
    resid_ls: np.ndarray       # (N,) its relative residual (inf where it has none)
    has_highlight: np.ndarray  # (N,) bool: a light stands out above the Lambertian prediction
    hl_start: np.ndarray       # (N, 3) the half-vector of that light (a second start)
    rng: np.random.Generator   # draws the fit and profile pixels
    nrm: np.ndarray            # (N, 3) current normals
    kd: np.ndarray             # (N, C) K_d of the pixels solved so far
    refined: np.ndarray        # (N,) bool: solved by the BRDF-aware step
    shadow: np.ndarray         # (N, m) lights left out
    rel: np.ndarray            # (N,) relative residual
    vm: str = ""               # the current material's diffuse part (volume model)
    outlier: np.ndarray = None  # (N,) bool: the initial solution left a light out as a shadow or a highlight
    mean_lights: np.ndarray = None   # per-pixel lights: the image's mean (m, 3) for the correction, None: these pixels'
    minima_gap: np.ndarray = None    # (N,) `search_minima`'s relative gap of the two best minima' costs (NaN: none)
    searched: dict = None            # `neighbour_round`'s first steps: (pixels tried, moved) of each

    @classmethod
    def start(cls, images, light_dirs, channel, saturation, base, settings, seed):
        """The valid pixels of `base` (the initial solution, a PSResult), with least squares."""
        m, h, w, c = images.shape
        idx = np.flatnonzero(base.valid.ravel())
        flat = images.reshape(m, h * w, c)
        s_all = _pixel_dirs(light_dirs, idx)                          # (m, 3) or (N, m, 3)
        nrm = base.normal.reshape(-1, 3)[idx].astype(np.float32)
        alb = base.albedo.reshape(-1, c)[idx]
        from ._ps_li_pixels_jit import channel_and_usable     # numba loads only when li_alternating runs
        values, all_ok = channel_and_usable(flat, idx, channel, saturation)     # (N, m) each
        has_highlight, hl_start = _highlight_starts(values, all_ok, nrm, s_all, alb[:, channel])
        nrm_ls, resid_ls = _least_squares_level(values, all_ok, s_all)
        return cls(settings=settings, shape=(h, w), channel=channel, flat=flat, idx=idx, s_all=s_all,
                   all_ok=all_ok, alb=alb, nrm0=nrm.copy(), nrm_ls=nrm_ls, resid_ls=resid_ls,
                   has_highlight=has_highlight, hl_start=hl_start, rng=np.random.default_rng(seed), nrm=nrm,
                   outlier=(base.shadow | base.specular).reshape(-1, m)[idx].any(1),
                   kd=np.zeros((idx.size, c), np.float32), refined=np.zeros(idx.size, bool),
                   shadow=base.shadow.reshape(-1, m)[idx].copy(), rel=base.residual.reshape(-1)[idx].copy(),
                   vm=settings.diffuse_models[0])

    def gather(self, sel):
        """(n, m, C) float32 values of the pixels `sel` (indices into the N)."""
        return np.ascontiguousarray(np.transpose(self.flat[:, self.idx[sel], :], (1, 0, 2)), dtype=np.float32)

    def lights_of(self, sel):
        return self.s_all if self.s_all.ndim == 2 else self.s_all[sel]

    def draw(self, trust):
        """Sorted fit pixels: `fit_pixels` of `trust` (all if fewer), drawn without replacement."""
        return np.sort(self.rng.choice(trust, min(self.settings.fit_pixels, trust.size), replace=False))

    def refine(self, sel, sigma, n_i, first_round=True, engine=None, step_tol=ROUND_STEP_TOL, diffuse_vm=None,
               table_grid=None):
        """RefineResult of the pixels `sel` solved against (σ, n_i).

        First round: the current normal and the highlight start, and for a metal's lobe a search of
        the hemisphere where the current normal explains the pixel poorly (facette.fit._orientation:
        a metal has no diffuse part, so the Lambertian initial normals say nothing there); later
        rounds start from the previous round's normals, already near, so one start and fewer steps do. Pixel blocks on
        WORKERS threads (numpy releases the GIL in its loops)."""
        st = self.settings
        engine = st.engine if engine is None else engine
        vm = self.vm if diffuse_vm is None else diffuse_vm      # the current material's, unless given
        out = {}

        def block(a):
            sub = sel[a:a + (BLOCK if self.s_all.ndim == 3 else BLOCK_COMPILED)]
            e, lights, ok = self.gather(sub), self.lights_of(sub), self.all_ok[sub]
            if first_round:
                # the highlight start doubles the cost where it is tried (most pixels under 96 lights):
                # on every pixel only with highlight_start="all" (module doc of _ps_li)
                hl = self.has_highlight[sub] if (st.highlight_start == "all" or sel.size <= 4 * st.fit_pixels) \
                    else np.zeros(sub.size, bool)
                out[a] = refine_normals_li(e, lights, self.nrm[sub], sigma, n_i, usable=ok, iterations=st.iterations,
                                           extra_starts=[self.hl_start[sub]] if hl.any() else None, extra_rows=hl,
                                           engine=engine, volume_model=vm, step_tol=step_tol, table_grid=table_grid,
                                           search=is_metal(n_i))
            else:
                out[a] = refine_normals_li(e, lights, self.nrm[sub], sigma, n_i, usable=ok,
                                           iterations=max(2, st.iterations // 2), engine=engine,
                                           volume_model=vm, step_tol=step_tol)

        if self.s_all.ndim == 2:
            # the compiled per-pixel solve runs its own threads: blocks in turn (memory only)
            for a in range(0, sel.size, BLOCK_COMPILED):
                block(a)
        else:
            run_blocks(block, range(0, sel.size, BLOCK))
        return join_blocks([out[a] for a in sorted(out)])

    def refine_round(self, todo, sigma, n_i):
        """RefineResult of a round's pixels `todo` (in their order): those an earlier round solved
        start from their normal alone (`refine`'s later-round form), those new to the BRDF-aware
        step (the refit's lobe took them in) get the first round's starts. Round 2 used to give
        every pixel the first round's starts as soon as one was new (DiLiGenT cat: 276 new of
        44 588, and the highlight start re-tried on 31 427 pixels round 1 had already chosen for)."""
        new = ~self.refined[todo]
        if new.all() or not new.any():
            return self.refine(todo, sigma, n_i, first_round=bool(new.all()))
        parts = [self.refine(todo[new], sigma, n_i, first_round=True),
                 self.refine(todo[~new], sigma, n_i, first_round=False)]
        back = np.argsort(np.concatenate([np.flatnonzero(new), np.flatnonzero(~new)]), kind="stable")
        joined = join_blocks(parts)
        return RefineResult(**{k: getattr(joined, k)[back] for k in _FIELDS})

    def split_levels(self, pix, sigma, n_i):
        """(lobe, lam_ok, todo) of the pixels `pix`: the BRDF-aware step where the lobe matters
        (`todo`); the rest keeps the initial solution (its shadow test) unless least squares
        already explained it (`lam_ok`: then corrected here)."""
        lobe = _in_lobe(self.nrm0[pix], self.lights_of(pix), sigma) | self.has_highlight[pix]
        lam_ok = (self.resid_ls[pix] < self.settings.t_residual) & self.all_ok[pix].all(1) & ~lobe
        lam_pix = pix[lam_ok]
        if lam_pix.size:
            lights = self.lights_of(lam_pix) if self.mean_lights is None else self.mean_lights
            self.nrm[lam_pix] = _lambertian_correction(self.nrm_ls[lam_pix], lights, sigma, n_i, self.vm,
                                                       passes=CORRECTION_PASSES if self.s_all.ndim == 2 else 1)
            self.refined[lam_pix] = False
        return lobe, lam_ok, pix[~lam_ok & lobe]

    def choose_model(self, fsel, pix):
        """Round 1 (`choose_material_model`): lobe or none, which diffuse part, and (σ, n_i), on the
        profile pixels: the fit pixels `fsel`, fewer under many lights (PROFILE_VALUES values);
        the candidates scored again, and the choice made, on a draw of all the material's pixels
        `pix` (the check below)."""
        profile = self.profile_of(fsel)
        return choose_material_model(self.gather(profile), self.lights_of(profile), self.all_ok[profile],
                                     self.solver(profile), self.settings.diffuse_models, check=self.check_of(pix))

    def profile_of(self, fsel):
        """The model choice's profile pixels: of the fit pixels `fsel`, fewer under many lights
        (PROFILE_VALUES values in all, at least 100 pixels), drawn with the pixels' generator."""
        m = self.flat.shape[0]
        return fsel[np.sort(self.rng.choice(fsel.size, min(fsel.size, max(100, PROFILE_VALUES // m)), replace=False))]

    def check_of(self, pix):
        """(values, lights, usable, solve) of the model choice's check pixels: a draw of all the
        material's pixels `pix`, where each diffuse part's best candidate is scored again and the
        choice made (`choose_material_model`'s check): the fit pixels are the brighter, less oblique
        half (the σ fit's signal to noise), and there the diffuse parts tie, since they differ most at
        oblique angles (Mitsuba sphere paint 0.10: profile costs LI 0.0946, coupled 0.0948; on the
        material's pixels 27 % apart). The draw has a generator of its own: the fit pixels' draws stay
        as they were."""
        sel = np.sort(self.rng.spawn(1)[0].choice(pix, min(self.settings.fit_pixels, pix.size), replace=False))
        return self.gather(sel), self.lights_of(sel), self.all_ok[sel], self.solver(sel)

    def solver(self, sel):
        """solve(σ, n_i, volume_model, search=True, grid=PROFILE_TABLE_GRID) -> (len(sel), 3): the
        normals of the pixels `sel` solved against a candidate model, as the model choice and its
        warm-up ask (`_li_model`, `_ps_li_start`). On the compiled engine where it applies (distant
        lights), on a coarse table of the volume part (PROFILE_TABLE_GRID), converged, with the
        highlight start (one start and half the steps moved the simulated scan's choice from σ 0.050,
        n_i 1.20 to 0.035, 1.30: 0.38° -> 0.62°). The warm-up's too (search=False; DiLiGenT 12
        lights: 11.9 -> 7.7 s over the six objects), but a metal's lobe's on the arrays: it may be
        coloured, and the compiled engine solves on the channels' mean (Mitsuba metallic paint
        sphere: 1.26° -> 1.08°)."""
        engine = self.settings.engine
        arrays = "arrays" if engine == "auto" else engine
        compiled = "compiled" if engine == "auto" and self.s_all.ndim == 2 else arrays

        def solve(sigma, n_i, vm, search=True, grid=PROFILE_TABLE_GRID):
            eng = arrays if not search and is_metal(n_i) else compiled
            return self.refine(sel, sigma, n_i, engine=eng, diffuse_vm=vm, table_grid=grid).normals
        return solve

    def lambertian_material(self, pix):
        """Pixels of `pix` given least squares (a material without an interface); their count."""
        # least squares over every light is the Lambertian answer where it explains the pixel (every
        # light usable, residual < t_residual); a robust init's trimming only adds noise there
        # (Mitsuba plaster relief: least squares 1.41°, rank_trimmed 1.54°)
        # ... and where the robust start left no light out (none below half or above 1.5 x its fit): its
        # trimming there drops direct light (a concave wall's dim values, its gathered light's noise
        # over t_residual: Mitsuba bowl in plaster, 12 lights, after the removal 1.45 -> 0.96°)
        explained = (self.resid_ls[pix] < self.settings.t_residual) | ~self.outlier[pix]
        lam = pix[explained & self.all_ok[pix].all(1)]
        self.nrm[lam] = self.nrm_ls[lam]
        return int(lam.size)

    def solve_from(self, sel, start, sigma, n_i, iterations, extra=None, **options):
        """The BRDF-aware solves (RefineResult, one per block, in order) of the pixels `sel` from the
        normals `start` (len(sel), 3), and from `extra` too where given (the lower cost kept),
        against the current material's diffuse part; options: of refine_normals_li (step_tol)."""
        size = BLOCK_COMPILED if self.s_all.ndim == 2 else BLOCK
        return [refine_normals_li(self.gather(sel[a:a + size]), self.lights_of(sel[a:a + size]), start[a:a + size],
                                  sigma, n_i, usable=self.all_ok[sel[a:a + size]], iterations=iterations,
                                  extra_starts=None if extra is None else [extra[a:a + size]],
                                  engine=self.settings.engine, volume_model=self.vm, **options)
                for a in range(0, sel.size, size)]

    def neighbour_round(self, pix, sigma, n_i, rounds=NEIGHBOUR_ROUNDS):
        """The pixels of `pix` the BRDF-aware step solved whose normal is more than
        settings.neighbour_deg from the mean of their 5 × 5 neighbours (`_neighbour_means`)
        solved again from that mean and from their normal, keeping the start of lower robust
        cost: the pixel's own values choose, the neighbours only propose a start (under few lights
        the per-pixel cost has several minima, and a pixel's solve may stop in another one than its
        neighbours'). Repeated while normals move, at most `rounds` times: a later round tries
        only the pixels within the 5 × 5 block of one that moved, whose proposed start changed.
        Returns (pixels tried, pixels whose normal moved by > 1°, per round). The minima search
        (`search_minima`) runs first (settings.minima_search): the neighbours then spread what it found."""
        cand = pix[self.refined[pix]]
        st = self.settings
        self.searched = {"minima_search": self.search_minima(cand, sigma, n_i) if st.minima_search else (0, 0),
                         "isolated_flags": self.solve_isolated_flags(cand, sigma, n_i) if st.isolated_flags else (0, 0)}
        tried, moved = [], []
        for _ in range(rounds):
            mean = _neighbour_means(self.nrm, self.idx, self.shape)
            far = cand[angle_deg(self.nrm[cand], mean[cand]) > self.settings.neighbour_deg]
            if not far.size:
                break
            rr = join_blocks(self.solve_from(far, mean[far], sigma, n_i, self.settings.iterations,
                                             extra=self.nrm[far]))
            went = far[angle_deg(rr.normals, self.nrm[far]) > 1.0]
            self.store(far, rr)
            tried.append(int(far.size))
            moved.append(int(went.size))
            if not went.size:
                break
            cand = cand[_near(went, cand, self.idx, self.shape)]
        return tried, moved

    def search_minima(self, cand, sigma, n_i):
        """The minima search (facette.fit._ps_li_minima) of the pixels of `cand` whose normal is more
        than SEARCH_ABOVE_DEG from their 5 × 5 neighbours' mean: a pixel whose search found a minimum
        of lower robust cost is solved again from it (`solve_from`: its K_d, kept lights, residual).
        Distant lights, at most SEARCH_MAX_LIGHTS of them; not a metal's lobe (it may be coloured,
        and the search compares costs on the channels' mean: Mitsuba gold sphere 9.50 -> 9.72°). The
        relative gap of the costs of each searched pixel's two best minima goes to `minima_gap`.
        Returns (pixels searched, pixels whose normal moved by > 1°)."""
        if self.minima_gap is None:
            self.minima_gap = np.full(self.idx.size, np.nan, np.float32)
        if not self._searched_under(n_i):
            return 0, 0
        mean = _neighbour_means(self.nrm, self.idx, self.shape)
        sel = cand[angle_deg(self.nrm[cand], mean[cand]) > SEARCH_ABOVE_DEG]
        if not sel.size:
            return 0, 0
        mm = search_pixel_minima(self.gather(sel), self.all_ok[sel], self.nrm[sel], self.s_all, sigma, n_i, self.vm)
        self.minima_gap[sel] = relative_gap(mm.cost_best, mm.cost_second)
        return int(sel.size), self._move_to_cheaper(sel, mm, sigma, n_i, mean[sel])

    def solve_isolated_flags(self, cand, sigma, n_i):
        """The pixels of `cand` with a light left out as a cast shadow that all their neighbours keep
        (facette.fit._ps_li_flags) solved again from their neighbours' mean; each moves where that
        minimum's robust cost over every usable light is lower. Under the lights `search_minima` runs
        under. Returns (pixels tried, pixels whose normal moved by > 1°)."""
        if not self._searched_under(n_i):
            return 0, 0
        sel = cand[isolated_flags(self.shadow, self.all_ok, self.idx, self.shape)[cand]]
        if not sel.size:
            return 0, 0
        mean = _neighbour_means(self.nrm, self.idx, self.shape)[sel]
        mm = search_pixel_minima(self.gather(sel), self.all_ok[sel], self.nrm[sel], self.s_all, sigma, n_i, self.vm,
                                 keep=1, starts=mean[:, None, :])
        return int(sel.size), self._move_to_cheaper(sel, mm, sigma, n_i, mean)

    def _searched_under(self, n_i):
        """Whether these lights and this material are searched: distant lights, at most
        SEARCH_MAX_LIGHTS, not a metal's lobe (`search_minima`)."""
        return self.s_all.ndim == 2 and self.s_all.shape[0] <= SEARCH_MAX_LIGHTS and not is_metal(n_i)

    def _move_to_cheaper(self, sel, mm, sigma, n_i, mean):
        """The pixels of `sel` whose `Minima` `mm` found a cheaper minimum > 1° away, nearer their
        neighbours' `mean` than their normal (fit._ps_li_minima's doc: toward the neighbours only), solved
        from it (`solve_from`: their K_d, kept lights, residual); how many moved by > 1°."""
        go = (mm.cost_best < mm.cost_here) & (angle_deg(mm.normals, self.nrm[sel]) > 1.0)
        go &= angle_deg(mm.normals, mean) < angle_deg(self.nrm[sel], mean)
        if not go.any():
            return 0
        todo = sel[go]
        rr = join_blocks(self.solve_from(todo, mm.normals[go], sigma, n_i, self.settings.iterations))
        went = int((angle_deg(rr.normals, self.nrm[todo]) > 1.0).sum())
        self.store(todo, rr)
        return went

    def settle_shadows(self, pix, sigma, n_i):
        """The lights the BRDF-aware solve left out of the pixels of `pix` stay cast shadows only
        where their value is also below CAST_SHADOW_RATIO x the diffuse part at the final normal
        (a shadow takes the direct light away, the diffuse part's too). The solve decided at its
        start normal, against the whole model: a narrow lobe a little off there flags the values
        of its own tail, which the BRDF fit's samples then left out (Mitsuba paint σ 0.05 sphere:
        337-587 flags over five draws and the fitted σ 0.0506-0.0579; after this 2 flags and
        0.0506-0.0526). Returns the number of flags lifted."""
        sel = pix[self.refined[pix] & self.shadow[pix].any(1)]
        lifted = 0
        for a in range(0, sel.size, BLOCK):
            p = sel[a:a + BLOCK]
            _, b = li_shading_terms(self.nrm[p], self.lights_of(p), sigma, n_i, specular=False,
                                    volume_model=self.vm)
            kappa = kappa_from_kd(np.clip(self.kd[p, self.channel], 0, 1), n_i, self.vm, sigma)
            values = self.flat[:, self.idx[p], self.channel].T
            was = self.shadow[p]
            self.shadow[p] = was & (values < CAST_SHADOW_RATIO * b * kappa[:, None])
            lifted += int(was.sum() - self.shadow[p].sum())
        return lifted

    def store(self, todo, rr):
        """The BRDF-aware solve `rr` of the pixels `todo` written back."""
        self.nrm[todo] = rr.normals
        self.kd[todo] = rr.kd
        self.refined[todo] = True
        self.rel[todo] = rr.rel_residual
        self.shadow[todo] = self.all_ok[todo] & ~rr.used


def _near(went, cand, idx, shape):
    """(len(cand),) bool: the pixels `cand` within the 5 × 5 block of a pixel of `went` (indices
    into the valid pixels `idx` of an image of `shape`)."""
    from scipy.ndimage import maximum_filter
    grid = np.zeros(shape[0] * shape[1], bool)
    grid[idx[went]] = True
    return maximum_filter(grid.reshape(shape), size=5, mode="constant").ravel()[idx[cand]]


def _neighbour_means(nrm, idx, shape):
    """(N, 3) unit mean of the normals of each pixel's valid neighbours in its 5 × 5 block (itself
    left out; a pixel without any keeps its own normal)."""
    from scipy.ndimage import uniform_filter
    h, w = shape
    grid = np.zeros((3, h * w), np.float32)
    grid[:, idx] = nrm.T
    sums = np.stack([uniform_filter(g.reshape(h, w), size=5, mode="constant") for g in grid]).reshape(3, -1)
    mean = (25 * sums[:, idx] - grid[:, idx]).T            # uniform_filter's mean × 25: the block's sum
    ln = np.linalg.norm(mean, axis=1, keepdims=True)
    return np.where(ln > 1e-6, mean / np.maximum(ln, 1e-6), nrm).astype(np.float32)


def _in_lobe(normals, lights, sigma):
    """(N,) True where some light is inside the fitted lobe (tan θ_h < LOBE_TAN σ)."""
    from ._ps_li_pixels_jit import any_light_in_lobe     # numba loads only when li_alternating runs
    h = lights + np.float32([0, 0, 1])
    h = h / np.linalg.norm(h, axis=-1, keepdims=True)
    # tan θ_h < k  ⟺  cos θ_h > 1 / √(1 + k²) (for cos θ_h > 0)
    k2 = np.float32((LOBE_TAN * sigma) ** 2)
    return any_light_in_lobe(normals, h, np.float32(np.sqrt(1 / (1 + k2))))


def _least_squares_level(values, all_ok, lights, chunk=262144):
    """The Lambertian level's least squares over every light ((N, 3) unit normals, (N,) relative
    residual): its residual decides which pixels it explains, and its normal is what the tabulated
    correction models (the initial solution's residual is on the lights it kept, its normal would
    bias the correction). Only a pixel with every light usable, whose lights span 3-D, can be at that
    level: the others get an infinite residual. From the values the alternation gathered already (a
    second whole `ps_woodham1980` took 1.3 s of the 12 MP scan's photometric stereo), by its solve
    (facette.recon._ps._ls_normals)."""
    n_pix = len(values)
    nrm = np.zeros((n_pix, 3), np.float32)
    resid = np.full(n_pix, np.inf, np.float32)

    def block(a):
        sl = slice(a, a + chunk)
        e, full = values[sl].T, all_ok[sl].all(1)                     # (m, n) light-major, as recon's
        s = lights if lights.ndim == 2 else lights[sl]
        # distant lights: one pseudo-inverse for every pixel (a pixel not `full` is dropped below)
        g = _ls_normals(e, s, np.ones(e.shape, bool) if s.ndim == 2 else np.broadcast_to(full, e.shape))
        g_len = np.linalg.norm(g, axis=0)
        e_len = np.linalg.norm(e, axis=0)
        good = full & (g_len > 1e-12) & (e_len > 0) & np.isfinite(g_len)
        g = np.where(good, g, 0)
        nrm[sl] = (g / np.where(good, g_len, 1)).T
        resid[sl] = np.where(good, np.linalg.norm(e - _shading(s, g), axis=0) / np.where(good, e_len, 1), np.inf)

    run_blocks(block, range(0, n_pix, chunk))
    return nrm, resid


def _lambertian_correction(normals, lights, sigma, n_i, volume_model, grid=65, passes=CORRECTION_PASSES):
    """(N, 3) corrected normals for pixels outside the lobe, from least-squares normals.

    Outside the specular lobe the model is E ≈ B(n, s) κ, whose least-squares (Lambertian)
    normal n_LS(n) differs from n by a smooth bias δ(n) = n − n_LS(n) (the Fresnel transmissions
    of the volume part, eq 3.15, tilt it by up to a few degrees at oblique normals). That bias
    depends on the normal alone (κ cancels), so it is tabulated once per (σ, n_i) on a grid of
    normals and interpolated, and n = n_LS + δ(n) is solved by `passes` fixed-point passes from
    n = n_LS (one pass, δ taken at n_LS, left 0.15-0.38° at the 95th percentile at 40-70° of tilt
    on the model's own values, σ 0.1-0.2; three passes 0.09-0.11°). Cost: grid² pixels, not N.
    lights : (m, 3), or (N, m, 3) whose mean direction is used (near lights vary little; or their
        mean over a whole image, given as (m, 3) with passes=1, for a band of it); then one
        pass only: the table is the mean directions', and solving its fixed point moved the
        Mitsuba near-light sphere from 0.26° to 0.31°.
    """
    s = lights if lights.ndim == 2 else lights.mean(axis=0)
    s = s / np.linalg.norm(s, axis=1, keepdims=True)
    passes = passes if lights.ndim == 2 else 1      # (m, 3) given for per-pixel lights: the caller's passes
    u = np.linspace(-1, 1, grid, dtype=np.float32)
    gx, gy = np.meshgrid(u, u)
    r2 = gx * gx + gy * gy
    inside = r2 < 0.995
    gn = np.stack([gx, gy, np.sqrt(np.maximum(1 - r2, 0))], axis=-1).reshape(-1, 3)
    gn[~inside.ravel()] = [0, 0, 1]
    _, b = li_shading_terms(gn, s, sigma, n_i, specular=False, volume_model=volume_model)
    g = b @ np.linalg.pinv(s).T.astype(np.float32)                 # least squares of the model's values
    n_ls = g / np.maximum(np.linalg.norm(g, axis=1, keepdims=True), 1e-12)
    delta = (gn - n_ls).reshape(grid, grid, 3)
    delta[~inside] = 0
    def corrected(n_ls, at):         # n_LS + δ(at), δ looked up bilinearly, unit
        fx = np.clip((at[:, 0] + 1) / 2 * (grid - 1), 0, grid - 1.001)
        fy = np.clip((at[:, 1] + 1) / 2 * (grid - 1), 0, grid - 1.001)
        ix, iy = fx.astype(int), fy.astype(int)
        wx, wy = (fx - ix)[:, None], (fy - iy)[:, None]
        d = ((1 - wx) * (1 - wy) * delta[iy, ix] + wx * (1 - wy) * delta[iy, ix + 1]
             + (1 - wx) * wy * delta[iy + 1, ix] + wx * wy * delta[iy + 1, ix + 1])
        c = n_ls + d
        return (c / np.linalg.norm(c, axis=1, keepdims=True)).astype(np.float32)

    out = corrected(normals, normals)
    # the later passes where the bias is not negligible (a flat table under a ring of lights has
    # none: at 12 MP those pixels were most of the Lambertian level's)
    sel = np.flatnonzero(np.linalg.norm(out - normals, axis=1) > 1e-4)
    for _ in range(passes - 1):
        out[sel] = corrected(normals[sel], out[sel])
    return out


def _highlight_starts(values, usable, normals, lights, albedo):
    """A second start per pixel: the half-vector of the light that most exceeds the Lambertian
    prediction of the initial solution (a highlight says where the normal is), tried where that
    light stands out (≥ 10 % of the pixel's mean value). values, usable : (N, m); normals (N, 3);
    lights (m, 3) or (N, m, 3); albedo (N,). Returns (has_highlight (N,) bool, starts (N, 3))."""
    from ._ps_li_pixels_jit import brightest_excess     # numba loads only when li_alternating runs
    has_highlight, brightest = brightest_excess(values, usable, normals, lights, albedo / np.pi)
    half = lights + np.float32([0, 0, 1])
    half = (half / np.linalg.norm(half, axis=-1, keepdims=True)).astype(np.float32)
    return has_highlight, (half[brightest] if half.ndim == 2 else half[np.arange(len(normals)), brightest])
