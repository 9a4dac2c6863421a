"""The virtual hemispherical sensor: equal-area cells (Beckers & Beckers 2012) that average
reflectance samples, a low-pass filter whose strength is the cell size (thesis §4.2.2).

Partition (thesis eq 4.12-4.14), from the polar cap of half-angle theta_0 (k_0 = 1 cell):
    theta_{j+1} = theta_j + 2 sqrt(pi / k_j) sin(theta_j / 2)      (4.14)
    r_j = 2 sin(theta_j / 2)  (Lambert equal-area radius)           (4.12)
    k_{j+1} = k_j (r_{j+1} / r_j)^2  (cells inside ring j+1)        (4.13)
k_j counts all the cells inside ring j's outer edge, so ring j+1 holds k_{j+1} - k_j cells.
The thesis prints r_{j+1} = 2 sin(theta_j / 2) (an index off by one: the radius belongs to the
same edge as its angle). The counts are rounded, the last edge put at 90 deg, and the edges
recomputed from the counts so that every cell has exactly the same solid angle
(2 pi / N sr); a last ring thinner than half the previous one is merged into it.
"""
from dataclasses import dataclass

import numpy as np

__all__ = ["beckers_partition", "HemisphereSensor", "FilteredReflectance", "hemisphere_filter",
           "THETA0_DEG"]

THETA0_DEG = 3.0   # thesis §4.3.1: 3 deg is the recommended cell size (2 deg sharper, 6 deg smoother)


def beckers_partition(theta0):
    """Equal-area partition of the hemisphere (eq 4.12-4.14).

    theta0 : polar-cap half-angle in rad, in (0, pi/4].
    Returns (edges (R+1,) zenith angles of the ring edges in rad, edges[0] = 0, edges[-1] = pi/2;
    counts (R,) cells per ring, counts[0] = 1 for the cap).
    """
    if not (0 < theta0 <= np.pi / 4):
        raise ValueError(f"theta0 must be in (0, 45] degrees, got {np.degrees(theta0):.3g} deg")
    thetas, cum = [theta0], [1]
    while True:
        tj, kj = thetas[-1], cum[-1]
        tn = tj + 2 * np.sqrt(np.pi / kj) * np.sin(tj / 2)                       # eq 4.14
        kn = kj * (np.sin(tn / 2) / np.sin(tj / 2)) ** 2                        # eq 4.12-4.13
        if tn >= np.pi / 2:
            break
        thetas.append(tn)
        cum.append(max(int(round(kn)), kj + 1))
    total = int(round(cum[-1] * (np.sin(np.pi / 4) / np.sin(thetas[-1] / 2)) ** 2))
    last = total - cum[-1]
    if len(cum) > 1 and last < 0.5 * (cum[-1] - cum[-2]):
        cum[-1] = total                                  # merge a thin last ring
    else:
        cum.append(max(total, cum[-1] + 1))
    cum = np.array(cum, dtype=np.int64)
    total = cum[-1]
    r = np.sqrt(2.0 * cum / total)                      # equal-area radius, r(pi/2) = sqrt(2)
    edges = np.concatenate([[0.0], 2 * np.arcsin(np.clip(r / 2, 0, 1))])
    edges[-1] = np.pi / 2
    counts = np.diff(np.concatenate([[0], cum]))
    return edges, counts


@dataclass
class FilteredReflectance:
    """The sensor's output: mean BRDF per (incidence bin, observation cell), per channel.

    mean : (B, N, C) float64, NaN in empty cells; count : (B, N) int64 samples per cell.
    theta_s : (B,) incidence of each bin's centre (rad); s : (B, 3) the bin centre directions
    (phi_s = 0); o : (N, 3) observation cell centres (local frame, n = +z); edges, counts:
    the partition (also used for the incidence bins).
    """
    mean: np.ndarray
    count: np.ndarray
    theta_s: np.ndarray
    s: np.ndarray
    o: np.ndarray
    edges: np.ndarray
    counts: np.ndarray

    def flat(self, min_count=1):
        """Non-empty cells as flat arrays (s (K, 3), o (K, 3), f (K, C), count (K,)): the input
        of a BRDF fit."""
        b, c = np.nonzero(self.count >= min_count)
        return self.s[b], self.o[c], self.mean[b, c], self.count[b, c]


class HemisphereSensor:
    """Accumulates samples into equal-area cells; incidence binned by the same rings.

    theta0_deg : cap half-angle (deg), default 3. channels : number of colour channels.
    Call `add(s_local, o_local, f)` any number of times (chunks), then `result()`.
    """

    def __init__(self, theta0_deg=THETA0_DEG, channels=3):
        self.edges, self.counts = beckers_partition(np.radians(theta0_deg))
        self.start = np.concatenate([[0], np.cumsum(self.counts)[:-1]])
        self.n_cells = int(self.counts.sum())
        self.n_bins = len(self.counts)
        self.channels = channels
        self._sum = np.zeros((self.n_bins * self.n_cells, channels))
        self._cnt = np.zeros(self.n_bins * self.n_cells, np.int64)
        # Rings are found from u = 1 - cos(theta) (proportional to the equal-area r^2) with a
        # table finer than the thinnest ring, then one comparison: no arccos, no binary search.
        self._u_edges = 1.0 - np.cos(self.edges)
        self._u_edges[-1] = 1.0
        n_lut = 4 * max(self.n_cells, 1024)
        self._lut_scale = n_lut
        self._lut = np.clip(np.searchsorted(self._u_edges, np.arange(n_lut + 1) / n_lut,
                                            side="right") - 1, 0, self.n_bins - 1)
        self._u_next = np.append(self._u_edges[1:], np.inf)

    def ring_of(self, theta):
        """(K,) ring index of zenith angles theta (rad)."""
        return self.ring_of_cos(np.cos(np.asarray(theta, dtype=np.float64)))

    def ring_of_cos(self, cos_theta):
        u = 1.0 - np.clip(cos_theta, 0.0, 1.0)
        ring = self._lut[(u * self._lut_scale).astype(np.int64)]
        return np.minimum(ring + (u >= self._u_next[ring]), self.n_bins - 1)

    def cell_of(self, o_local):
        """(K,) cell index of local directions (K, 3) with o_z >= 0."""
        phi = np.arctan2(o_local[:, 1], o_local[:, 0])           # (-pi, pi]
        ring = self.ring_of_cos(o_local[:, 2])
        k = self.counts[ring]
        j = np.minimum(((phi + np.pi) / (2 * np.pi) * k).astype(np.int64), k - 1)
        return self.start[ring] + j

    def add(self, s_local, o_local, f):
        """Accumulate samples: s_local, o_local (K, 3) local-frame unit vectors (phi_s = 0),
        f (K, C). Non-finite values and directions below the horizon are ignored."""
        self.add_angles(np.asarray(s_local)[:, 2], np.asarray(o_local), f)

    def add_angles(self, cos_theta_s, o_local, f):
        """As `add`, with the incidence given by cos(theta_s) (K,) alone."""
        f = np.asarray(f, dtype=np.float64).reshape(len(cos_theta_s), -1)
        if f.shape[1] != self.channels:
            raise ValueError(f"f has {f.shape[1]} channels, the sensor {self.channels}")
        ok = np.all(np.isfinite(f), 1) & (o_local[:, 2] >= 0) & (cos_theta_s >= 0)
        if not ok.all():
            cos_theta_s, o_local, f = cos_theta_s[ok], o_local[ok], f[ok]
        idx = self.ring_of_cos(cos_theta_s) * self.n_cells + self.cell_of(o_local)
        size = self._cnt.size
        self._cnt += np.bincount(idx, minlength=size)
        for ch in range(self.channels):
            self._sum[:, ch] += np.bincount(idx, weights=f[:, ch], minlength=size)

    def add_grid(self, cos_s, o_x, o_y, cos_o, e, keep, scale):
        """Accumulate a grid of samples without gathering them first (the fast path).

        cos_s, o_x, o_y : (m, P) incidence cosines and observation x, y in the local frame;
        cos_o : (P,) observation cosines (one per pixel: it does not depend on the light);
        e : (m, P, C) image values; scale : (m, P), f = e * scale; keep : (m, P) bool (e must
        be finite where kept). Left-out samples go to a discarded bin.
        """
        ring_o = self.ring_of_cos(cos_o)                               # (P,)
        k = self.counts[ring_o]
        phi = np.arctan2(o_y, o_x)
        j = np.minimum(((phi + np.pi) * (k / (2 * np.pi))).astype(np.int64), k - 1)
        idx = self.ring_of_cos(cos_s) * self.n_cells + (self.start[ring_o] + j)
        size = self._cnt.size
        idx = np.where(keep, idx, size).ravel()                      # size = the discard bin
        self._cnt += np.bincount(idx, minlength=size + 1)[:size]
        for ch in range(self.channels):
            w = (e[..., ch] * scale).ravel()                          # 0 where not kept
            self._sum[:, ch] += np.bincount(idx, weights=w, minlength=size + 1)[:size]

    def merge(self, other):
        """Add the accumulated samples of another sensor with the same partition."""
        if other._cnt.shape != self._cnt.shape or other.channels != self.channels:
            raise ValueError("cannot merge sensors with different partitions or channel counts")
        self._cnt += other._cnt
        self._sum += other._sum

    def centres(self):
        """(N, 3) cell-centre directions (equal-area middle of the ring, middle of the arc)."""
        r = 2 * np.sin(self.edges / 2)                             # equal-area radius of each edge
        mid = 2 * np.arcsin(np.sqrt((r[:-1] ** 2 + r[1:] ** 2) / 2) / 2)   # splits each ring's area
        mid[0] = 0.0                                               # the cap's centre is the pole
        out = []
        for j, k in enumerate(self.counts):
            phi = -np.pi + (np.arange(k) + 0.5) * 2 * np.pi / k
            out.append(np.stack([np.sin(mid[j]) * np.cos(phi), np.sin(mid[j]) * np.sin(phi),
                                 np.full(k, np.cos(mid[j]))], axis=1))
        return np.concatenate(out), mid

    def result(self):
        o, mid = self.centres()
        cnt = self._cnt.reshape(self.n_bins, self.n_cells)
        with np.errstate(invalid="ignore", divide="ignore"):
            mean = self._sum.reshape(self.n_bins, self.n_cells, self.channels) / cnt[..., None]
        theta_s = mid.copy()
        s = np.stack([np.sin(theta_s), np.zeros_like(theta_s), np.cos(theta_s)], axis=1)
        return FilteredReflectance(mean, cnt, theta_s, s, o, self.edges, self.counts)


def hemisphere_filter(samples, theta0_deg=THETA0_DEG):
    """Average `ReflectanceSamples` (or any object with s, o, f) on the virtual sensor.

    Returns `FilteredReflectance`. Thesis §4.2.2, eq 4.12-4.14; theta0 = 3 deg by default.
    """
    f = np.asarray(samples.f)
    sensor = HemisphereSensor(theta0_deg, channels=f.shape[1] if f.ndim == 2 else 1)
    sensor.add(np.asarray(samples.s), np.asarray(samples.o), f)
    return sensor.result()
