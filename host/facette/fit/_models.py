"""Parametrised models for the fits: a parameter vector ↔ predictions (N, C), with caching.

Vector layout: [σ, n_i, K_d_1 … K_d_C] for "li" and "cook_torrance"; [σ, K_d…] for
"oren_nayar"; [K_d…] for "lambert". σ and n_i are shared between channels (they describe
the geometry and the interface, thesis §4.2.2), K_d is per channel.

Everything that depends on (σ, n_i) alone (the specular lobe, the volume integral I and the
inter-reflection integral J) is cached per (σ, n_i), so changing K_d — and the finite-difference
columns of the Jacobian for K_d — costs a multiply-add.
"""
import threading

import numpy as np

from facette.brdf import (MODELS, diffuse_r_i, interreflection_integral_vcavity, interreflection_mixed_integral_vcavity,
                          li_kappa, li_specular, oren_nayar1994, prepare_directions, volume_integral)

__all__ = ["FitModel", "BOUNDS"]

# thesis §4.2.2: ρ ∈ [0, 1], σ ∈ [0, 2], n_i ∈ [1, 2.5]; σ starts at 1e-3 (σ = 0 is a Dirac lobe)
BOUNDS = {"sigma": (1e-3, 2.0), "n_i": (1.0, 2.5), "kd": (0.0, 1.0)}


class FitModel:
    """One model with fixed options, evaluated on fixed sample directions s, o (N, 3)."""

    def __init__(self, name, s, o, channels, distribution="beckmann", masking="smith", volume="quadrature",
                 interreflection=False, volume_options=None, n_paths=256, o_spread=None, n_i_max=None,
                 s_spread=None):
        name = MODELS.canonical(name)
        # a metal's lobe (Cook–Torrance only): n_i up to n_i_max, a real index of the metal's F0
        # (facette.brdf._fresnel.check_n_i)
        if n_i_max is not None and name != "cook_torrance":
            raise ValueError(f"n_i_max applies to Cook–Torrance (a metal's lobe beside a Lambertian part), not {name!r}")
        self.n_i_max = n_i_max
        if name == "li" and volume == "table":
            raise ValueError("volume='table' builds a table for every (σ, n_i) the fit visits (seconds each): "
                             "use volume='quadrature' (default, coarse nodes) or 'approx' to fit")
        self.name = name
        self.s, self.o = s, o
        self.channels = int(channels)
        self.distribution, self.masking, self.volume = distribution, masking, volume
        self.interreflection = bool(interreflection)
        self.volume_options = dict(volume_options or {})
        self.n_paths = int(n_paths)
        self.s_c, self.o_c = s, o  # cell centres
        if o_spread is not None:
            # each value is a cell average: evaluate at K directions spread over the cell and
            # average (exact for the K_d-free parts, which enter the model linearly). Only the
            # specular lobe varies inside a 2–6° cell; the volume parts are taken at the centre.
            # The incidence too where s_spread is given (its bin is as wide as a cell)
            self.s, self.o = (s[:, None, :] if s_spread is None else s_spread), o_spread
        self.up = self._mean((self.s[..., 2] > 0) & (self.o[..., 2] > 0))
        # the lobe's directions unit and broadcast once, not at each of the fit's evaluations
        self._s_unit, self._o_unit = (np.ascontiguousarray(a) for a in prepare_directions(self.s, self.o))
        self._cache = {}
        self._count_lock = threading.Lock()    # the fits' starts run on two threads (fit._fit)
        self.n_evaluations = 0
        if name in ("li", "cook_torrance"):
            self.names = ["sigma", "n_i"]
        elif name == "oren_nayar":
            self.names = ["sigma"]
        else:
            self.names = []
        self.n_shared = len(self.names)
        self.names = self.names + [f"kd[{c}]" for c in range(self.channels)]

    def _mean(self, x):
        x = np.asarray(x, dtype=float)
        return x.mean(axis=1) if x.ndim == 2 else x

    @property
    def n_params(self):
        return len(self.names)

    def bounds(self):
        lo, hi = [], []
        for nm in self.names:
            key = "kd" if nm.startswith("kd") else nm
            lo.append(BOUNDS[key][0])
            hi.append(self.n_i_max if key == "n_i" and self.n_i_max is not None else BOUNDS[key][1])
        return np.array(lo), np.array(hi)

    def split(self, p):
        p = np.asarray(p, dtype=float)
        shared = dict(zip(self.names[:self.n_shared], p[:self.n_shared]))
        return shared, p[self.n_shared:]

    def _parts(self, sigma, n_i):
        """K_d-free parts for these (σ, n_i), cached (a handful of entries)."""
        key = (round(float(sigma), 15), round(float(n_i), 15))
        parts = self._cache.get(key)    # one lookup: another thread's fit may clear the cache
        if parts is not None:
            return parts
        with self._count_lock:
            self.n_evaluations += 1
        spec = self._mean(li_specular(self._s_unit, self._o_unit, sigma, n_i, self.distribution, self.masking,
                                       prepared=True))
        parts = {"spec": spec}
        if self.name == "li":
            parts["I"] = self.up * volume_integral(self.s_c, self.o_c, sigma, n_i, self.distribution,
                                                   self.masking, self.volume, **self.volume_options)
            if self.interreflection:
                parts["J"] = interreflection_integral_vcavity(self.s_c, self.o_c, sigma, n_i, self.distribution,
                                                              n_paths=self.n_paths, rng=12345)
                parts["J1"] = interreflection_mixed_integral_vcavity(self.s_c, self.o_c, sigma, n_i,
                                                                     self.distribution, n_paths=self.n_paths,
                                                                     rng=12345)
        if len(self._cache) > 64:
            self._cache.clear()
        self._cache[key] = parts
        return parts

    def predict(self, p):
        """(N, C) model values for parameter vector p."""
        shared, kd = self.split(p)
        if self.name == "lambert":
            return self.up[:, None] * kd[None, :] / np.pi
        if self.name == "oren_nayar":
            key = ("on", round(float(shared["sigma"]), 15))
            ab = self._cache.get(key)
            if ab is None:
                with self._count_lock:
                    self.n_evaluations += 1
                a = self._mean(oren_nayar1994(self.s, self.o, 1.0, shared["sigma"], interreflection=False))
                b = self._mean(oren_nayar1994(self.s, self.o, 1.0, shared["sigma"], interreflection=True)) - a
                ab = self._cache[key] = (a, b)
            a, b = ab
            return a[:, None] * kd[None, :] + b[:, None] * kd[None, :] ** 2
        sigma, n_i = shared["sigma"], shared["n_i"]
        parts = self._parts(sigma, n_i)
        if self.name == "cook_torrance":
            return parts["spec"][:, None] + self.up[:, None] * kd[None, :] / np.pi
        kappa = li_kappa(kd, n_i, sigma, self.volume)
        out = parts["spec"][:, None] + parts["I"][:, None] * kappa[None, :]
        if self.interreflection:
            out = out + parts["J"][:, None] * kappa[None, :] ** 2 + parts["J1"][:, None] * kappa[None, :]
        return out

    def project_kd(self, p, values, weights):
        """Return p with its K_d replaced by the weighted least-squares optimum for its (σ, n_i).

        The LI and Cook–Torrance models are linear in κ = K_d/(π n_i² (1 − K_d r_i)) (resp. K_d/π)
        once σ and n_i are fixed (without inter-reflections), so each channel's best K_d has a
        closed form (variable projection). Lambert likewise; Oren–Nayar (K_d² term) is left as is.
        """
        p = np.array(p, dtype=float)
        if self.name == "oren_nayar" or (self.name == "li" and self.interreflection):
            return p
        shared, _ = self.split(p)
        w2 = weights**2
        if self.name == "lambert":
            spec, basis = 0.0, self.up[:, None] / np.pi
        else:
            parts = self._parts(shared["sigma"], shared["n_i"])
            spec = parts["spec"][:, None]
            basis = (parts["I"] if self.name == "li" else self.up / np.pi)[:, None]
        num = np.sum(w2 * basis * (values - spec), axis=0)
        den = np.sum(w2 * basis * basis, axis=0)
        coef = np.where(den > 0, num / np.where(den > 0, den, 1.0), 0.0)
        if self.name == "li":
            n = shared["n_i"]
            ri = diffuse_r_i(n, shared["sigma"], self.volume)
            kappa = np.clip(coef, 0.0, 1.0 / (np.pi * n * n * (1.0 - ri)))  # κ(K_d = 1)
            kd = kappa * np.pi * n * n / (1.0 + kappa * np.pi * n * n * ri)
        else:
            kd = coef
        p[self.n_shared:] = np.clip(kd, 0.0, 1.0)
        return p

    def describe(self):
        d = {"model": self.name}
        if self.name in ("li", "cook_torrance"):
            d.update(distribution=self.distribution, masking=self.masking)
        if self.name == "oren_nayar":
            d.update(distribution="gaussian", masking="vcavity")
        if self.name == "li":
            d.update(volume=self.volume, interreflection=self.interreflection)
        return d
