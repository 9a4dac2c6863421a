"""LED positions from mirror-sphere rays (the near-light model of `facette.calib.mirror_sphere`):
the normal under a highlight, the rays from two or more placements of the sphere meet at the LED; directions seen from an
origin once the LED's distance is known."""
import numpy as np

__all__ = ["sphere_rays", "light_positions_from_rays", "directions_from_origin"]


def _normal_at(circle, x, y):
    u = (x - circle.cx) / circle.r
    v = -(y - circle.cy) / circle.r
    rho2 = u * u + v * v
    if rho2 >= 1:
        raise ValueError(f"highlight at ({x:.1f}, {y:.1f}) lies outside the sphere's outline")
    return np.array([u, v, np.sqrt(1 - rho2)])


def sphere_rays(circle, highlights, shape, pixel_pitch_mm, sphere_radius_mm=None, center_z_mm=None):
    """Rays (origins (m, 3) mm, directions (m, 3)) from the sphere's highlights to the LEDs.

    The pixel pitch turns pixels into mm; with a known sphere radius and no pitch,
    the pitch is radius_mm / radius_px. The sphere centre's height is `center_z_mm`
    (default its radius: resting on the object plane z = 0).
    """
    if pixel_pitch_mm is None:
        if sphere_radius_mm is None:
            raise ValueError("give the pixel pitch or the sphere's radius in mm to place it")
        pixel_pitch_mm = sphere_radius_mm / circle.r
    h, w = shape[:2]
    r_mm = circle.r * pixel_pitch_mm if sphere_radius_mm is None else sphere_radius_mm
    c = np.array([(circle.cx - (w - 1) / 2) * pixel_pitch_mm,
                  ((h - 1) / 2 - circle.cy) * pixel_pitch_mm,
                  r_mm if center_z_mm is None else center_z_mm])
    origins, dirs = [], []
    for hl in highlights:
        n = _normal_at(circle, hl.x, hl.y)
        origins.append(c + r_mm * n)
        dirs.append(2 * n[2] * n - np.array([0.0, 0.0, 1.0]))
    return np.array(origins), np.array(dirs)


def light_positions_from_rays(origins, directions):
    """Least-squares point nearest to k ≥ 2 rays, for each LED.

    origins, directions : (k, m, 3) — placement k, LED m (mm; directions unit).
    Minimises Σ_k |(I − d dᵀ)(P − o)|². Returns (positions (m, 3) mm, rms distance
    of the rays to the point (m,) mm). Raises if the rays are (nearly) parallel:
    move the sphere further between placements.
    """
    o = np.asarray(origins, float)
    d = np.asarray(directions, float)
    if o.ndim == 2:
        o, d = o[:, None], d[:, None]
    if o.shape != d.shape or o.shape[0] < 2:
        raise ValueError("need rays from at least two sphere placements (k ≥ 2) to locate the "
                         "LEDs; with one placement only directions are known")
    d = d / np.linalg.norm(d, axis=-1, keepdims=True)
    P, rms = [], []
    for j in range(o.shape[1]):
        A = np.zeros((3, 3))
        b = np.zeros(3)
        projs = []
        for k in range(o.shape[0]):
            M = np.eye(3) - np.outer(d[k, j], d[k, j])
            A += M
            b += M @ o[k, j]
            projs.append(M)
        if np.linalg.cond(A) > 1e8:
            raise ValueError(f"LED {j}: the rays are parallel; move the sphere further between "
                             "placements (a few cm across the field)")
        p = np.linalg.solve(A, b)
        P.append(p)
        rms.append(np.sqrt(np.mean([np.sum((M @ (p - o[k, j])) ** 2) for k, M in enumerate(projs)])))
    return np.array(P), np.array(rms)


def directions_from_origin(origins, directions, distance_mm):
    """Directions of LEDs seen from the field's origin, given rays from the sphere.

    A highlight gives the direction from its point on the sphere (mm above and
    beside the object plane's origin); for LEDs at a finite `distance_mm` from the
    origin (the rig's nominal distance, e.g. 1500 mm) the LED is the point of the
    ray at that distance, and its direction from the origin differs from the ray's
    by about offset/distance (≈ 0.7° for a 76 mm sphere at 1.5 m). origins,
    directions (m, 3); returns unit (m, 3).
    """
    o = np.asarray(origins, float)
    d = np.asarray(directions, float)
    d = d / np.linalg.norm(d, axis=-1, keepdims=True)
    # |o + t d| = D  →  t = −o·d + sqrt((o·d)² − |o|² + D²)
    od = np.sum(o * d, axis=-1)
    disc = od ** 2 - np.sum(o * o, axis=-1) + float(distance_mm) ** 2
    if np.any(disc < 0) or not distance_mm > 0:
        raise ValueError("the LED distance must exceed the sphere's distance from the origin")
    p = o + (-od + np.sqrt(disc))[..., None] * d
    return p / np.linalg.norm(p, axis=-1, keepdims=True)
