"""Readers of PTM and HSH .rti files written from the formats' published definitions and the
reference viewers' loaders, not from facette's writers: the HP Labs "Polynomial Texture Map
(.ptm) File Format" v1.2 (2001) and RTIViewer's LRGBPtm / RGBPtm loaders (rows bottom first, coefficients
int((byte - bias) · scale), shown as L · RGB / 255 with L in byte units; the layout parsed by the bench's
reader written from those loaders, `facette.bench._relight_ptm_reader`: one reader of it); RTIViewer's and
Relight's HSH loaders (rows top first, byte / 255 · scale + bias, shown as value · 255), the
layout of RTIBuilder's own files."""
import struct
from pathlib import Path

import numpy as np
import pytest

from facette.bench._relight_ptm_reader import parse_ptm

# the folder holding shared/: beside the repository (a clone), or one further up (a git worktree)
_SHARED = next((p for p in Path(__file__).resolve().parents[3:5] if (p.parent / "shared").is_dir()),
               Path(__file__).resolve().parents[3]).parent
RTI_REFERENCE = _SHARED / "shared" / "data" / "rti_reference"


def needs_reference(path, what):
    """skipif mark: `what` (the sample files) is not here when `path` is absent, as in a user's
    clone without the shared data folder beside the repository."""
    return pytest.mark.skipif(not path.is_file(), reason=f"{what} not here ({path}): the shared data "
                              "folder beside the repository is absent in a user's clone")


def _header_tokens(data, pos, count):
    """`count` whitespace-separated ASCII tokens from pos, ending at a line end; returns
    (tokens, position of the first binary byte)."""
    tokens = []
    while len(tokens) < count:
        end = data.index(b"\n", pos)
        tokens.extend(data[pos:end].split())
        pos = end + 1
    assert len(tokens) == count, f"header line carries extra tokens: {tokens}"
    return tokens, pos


def read_ptm(path):
    """PTM_1.2 / PTM_FORMAT_LRGB -> dict(width, height, scale, bias, coeffs (H, W, 6) float,
    rgb (H, W, 3) uint8) with image row 0 at the top: RTIViewer's LRGBPtm layout (a0..a5 of every
    texel, then R, G, B of every texel, bottom row first), read by the one reader of that layout
    written from RTIViewer's loaders (`bench._relight_ptm_reader.parse_ptm`), not facette's."""
    ptm = parse_ptm(path)
    assert ptm["format"] == "PTM_FORMAT_LRGB", ptm["format"]
    return ptm


def read_ptm_rgb(path):
    """PTM_1.2 / PTM_FORMAT_RGB as RTIViewer's RGBPtm::loadData reads it (and HP's ptmlib, Perathoner's:
    the same layout): for red, green, blue in turn the six bytes a0..a5 of every texel, bottom row
    first; one scale and bias per term for the three channels (`parse_ptm`, as `read_ptm`).
    -> dict(width, height, scale, bias, coeffs (H, W, 3, 6) float) with image row 0 at the top."""
    ptm = parse_ptm(path)
    assert ptm["format"] == "PTM_FORMAT_RGB", ptm["format"]
    return ptm


def ptm_rgb_colour(ptm, light, rtiviewer=True):
    """RTIViewer's RGB rendering, in [0, 1]: each channel tobyte(its polynomial) / 255, from the integer
    coefficients RTIViewer keeps (rtiviewer=False: floats)."""
    coeffs = np.trunc(ptm["coeffs"]) if rtiviewer else ptm["coeffs"]
    return np.clip(ptm_luminance(coeffs, light[0], light[1]), 0.0, 255.0) / 255.0


def ptm_luminance(coeffs, lu, lv):
    """C = a0 Lu² + a1 Lv² + a2 Lu Lv + a3 Lu + a4 Lv + a5 (the document's §1.0)."""
    a = coeffs
    return (a[..., 0] * lu * lu + a[..., 1] * lv * lv + a[..., 2] * lu * lv + a[..., 3] * lu
            + a[..., 4] * lv + a[..., 5])


def ptm_colour(ptm, light, rtiviewer=True):
    """RTIViewer's LRGB rendering, in [0, 1]: the byte tobyte(L · RGB / 255) / 255, L clipped to
    >= 0 and evaluated from the integer coefficients RTIViewer keeps (rtiviewer=False: Relight's
    float ones)."""
    coeffs = np.trunc(ptm["coeffs"]) if rtiviewer else ptm["coeffs"]
    lum = np.maximum(ptm_luminance(coeffs, light[0], light[1]), 0.0)
    return np.minimum(lum[..., None] * ptm["rgb"] / 255.0, 255.0) / 255.0


def read_hsh(path):
    """#HSH1.2 .rti -> dict(width, height, terms, scale, bias, coeffs (H, W, 3, terms))."""
    data = Path(path).read_bytes()
    pos = 0
    while data[pos:pos + 1] == b"#":                 # comment lines
        pos = data.index(b"\n", pos) + 1
    tok, pos = _header_tokens(data, pos, 1)
    assert int(tok[0]) == 3, "file type 3 is HSH"
    tok, pos = _header_tokens(data, pos, 3)
    w, h, bands = map(int, tok)
    assert bands == 3
    tok, pos = _header_tokens(data, pos, 3)
    terms, basis_type, element_size = map(int, tok)
    assert element_size == 1
    scale = np.array(struct.unpack(f"<{terms}f", data[pos:pos + 4 * terms]))
    bias = np.array(struct.unpack(f"<{terms}f", data[pos + 4 * terms:pos + 8 * terms]))
    body = np.frombuffer(data, np.uint8, offset=pos + 8 * terms)
    assert body.size == w * h * 3 * terms
    q = body.reshape(h, w, 3, terms)                 # top row first; per pixel R, G, B blocks
    return dict(width=w, height=h, terms=terms, basis_type=basis_type, scale=scale, bias=bias,
                coeffs=q / 255.0 * scale + bias)


def hsh_weights(light, terms):
    """RTIViewer's hemispherical-harmonics weights at a light direction (x, y, z)."""
    phi = np.arctan2(light[1], light[0])
    ct = np.cos(np.arccos(np.clip(light[2], -1, 1)))
    ct2 = ct * ct
    s = np.sqrt(max(ct - ct2, 0.0))
    w = [1 / np.sqrt(2 * np.pi),
         np.sqrt(6 / np.pi) * np.cos(phi) * s,
         np.sqrt(3 / (2 * np.pi)) * (-1 + 2 * ct),
         np.sqrt(6 / np.pi) * s * np.sin(phi),
         np.sqrt(30 / np.pi) * np.cos(2 * phi) * (-ct + ct2),
         np.sqrt(30 / np.pi) * np.cos(phi) * (-1 + 2 * ct) * s,
         np.sqrt(5 / (2 * np.pi)) * (1 - 6 * ct + 6 * ct2),
         np.sqrt(30 / np.pi) * (-1 + 2 * ct) * s * np.sin(phi),
         np.sqrt(30 / np.pi) * (-ct + ct2) * np.sin(2 * phi)]
    return np.array(w[:terms])


def hsh_colour(rti, light):
    """Σ_k coeff_k · H_k(light) per channel, clipped to [0, 1] (shown as that · 255)."""
    return np.clip(rti["coeffs"] @ hsh_weights(light, rti["terms"]), 0.0, 1.0)


def asymmetric_scene(h=48, w=64):
    """Lambertian images of a dome in the top-left quadrant of a dark table, under the rig's
    12 lights: the top of the picture is row 0, x points right, y up (the camera frame).
    Returns (images (12, H, W, 3) float32, lights (12, 3), dome mask (H, W), centre (row, col))."""
    from facette.recon.synthetic import thesis_light_directions
    lights = thesis_light_directions()
    yy, xx = np.mgrid[0:h, 0:w].astype(float)
    cy, cx, r = h * 0.3, w * 0.3, min(h, w) * 0.22
    px, py = (xx - cx) / r, -(yy - cy) / r            # y up
    rho2 = px * px + py * py
    dome = rho2 < 0.95
    n = np.zeros((h, w, 3))
    n[..., 2] = 1.0
    nz = np.sqrt(np.clip(1 - rho2, 0, 1))
    n[dome] = np.stack([px, py, nz], -1)[dome]
    kd = np.where(dome[..., None], np.array([0.8, 0.6, 0.3]), 0.01)
    imgs = np.stack([kd * np.maximum(n @ s, 0.0)[..., None] for s in lights]).astype(np.float32)
    return imgs, lights, dome, (cy, cx)


def check_upright(picture_at, dome, centre):
    """The orientation checks on a relighting function picture_at(light) -> (H, W, 3) of
    `asymmetric_scene`: the dome is drawn in the top-left quadrant, light from the right
    lights its right half, light from the top its upper half; the picture is not black."""
    h, w = dome.shape
    cy, cx = centre
    s = np.sin(np.radians(30)), np.cos(np.radians(30))
    front = picture_at(np.array([0.0, 0.0, 1.0])).mean(-1)
    quad = [front[:h // 2, :w // 2].mean(), front[:h // 2, w // 2:].mean(),
            front[h // 2:, :w // 2].mean(), front[h // 2:, w // 2:].mean()]
    assert quad[0] > 1.5 * max(quad[1:]), f"the dome is not in the top-left quadrant: {quad}"
    assert front[dome].mean() > 0.25, f"the dome is nearly black: {front[dome].mean():.3f}"
    yy, xx = np.mgrid[0:h, 0:w]
    right = picture_at(np.array([s[0], 0.0, s[1]])).mean(-1)
    assert right[dome & (xx > cx + 2)].mean() > 1.3 * right[dome & (xx < cx - 2)].mean()
    top = picture_at(np.array([0.0, s[0], s[1]])).mean(-1)
    assert top[dome & (yy < cy - 2)].mean() > 1.3 * top[dome & (yy > cy + 2)].mean()
