"""Bayer sensor model of the camera (thesis eq 2.12–2.13): the HDR merge weighs frames with it,
the simulated camera renders with it.

Units used throughout:

- irradiance: electrons per second per photosite (e-/s), i.e. the thesis's E_p
  already multiplied by the quantum efficiency and the photosite area;
- exposure time: seconds;
- gain ``g``: electrons per digital number (e-/DN), the thesis's g;
- read noise: electrons RMS; dark current: electrons per second;
- black level, white level: DN (14-bit ADC: white level 16383).

Eq 2.12 gives the recorded value ΔV = min(E·t/g + ΔV0 + B, ΔVmax) with ΔV0 the
dark signal (here black level + dark current · t / g) and B a zero-mean noise of
variance (eq 2.13) Var(B) = E·t/g² + B_read²/g² + B_ADC²; the photon term is
Poisson (the thesis's "bruit de photon"), the read term Gaussian and the ADC term
uniform rounding (B_ADC² = 1/12 DN²). Dark-current electrons are Poisson too, so
they add D·t/g² to the variance: the full model used by the HDR merge is

    mean  = black + (E + D)·t / g                          (DN, below saturation)
    var   = (E + D)·t / g² + read² / g² + 1/12             (DN²)

Saturation happens at the full well (electrons) or at the white level (DN),
whichever comes first.
"""
from dataclasses import asdict, dataclass, replace

import numpy as np

__all__ = ["SensorModel", "DEFAULT_SENSOR", "bayer_mosaic_rggb", "SENSOR_KEYS"]

# Keys of the calibration profile's `sensor` section (calib/profile.py, schema 1).
SENSOR_KEYS = ("gain_e_per_dn", "read_noise_e", "dark_current_e_per_s", "black_level_dn",
                "white_level_dn")


def bayer_mosaic_rggb(rgb):
    """Interleave an (H, W, 3) array into an RGGB mosaic of shape (2H, 2W).

    Each RGB pixel becomes one 2×2 Bayer cell: R at (0, 0), G at (0, 1) and (1, 0),
    B at (1, 1). The two greens receive the same green value.
    """
    rgb = np.asarray(rgb)
    if rgb.ndim != 3 or rgb.shape[2] != 3:
        raise ValueError(f"expected an (H, W, 3) RGB array, got shape {rgb.shape}")
    h, w, _ = rgb.shape
    out = np.empty((2 * h, 2 * w), dtype=rgb.dtype)
    out[0::2, 0::2] = rgb[:, :, 0]
    out[0::2, 1::2] = rgb[:, :, 1]
    out[1::2, 0::2] = rgb[:, :, 1]
    out[1::2, 1::2] = rgb[:, :, 2]
    return out


@dataclass(frozen=True)
class SensorModel:
    """Linear CMOS sensor with shot, read, dark and quantisation noise (eq 2.12–2.13).

    Defaults are plausible values for a Nikon D300 at ISO 400 in 14-bit RAW (the
    thesis's camera); they are the simulated rig's nominal sensor.

    Attributes
    ----------
    gain_e_per_dn : float, > 0
        Conversion gain g, electrons per DN, at `iso`.
    read_noise_e : float, >= 0
        Read noise, electrons RMS (B_read).
    dark_current_e_per_s : float, >= 0
        Dark current, electrons per second per photosite.
    black_level_dn : int, >= 0
        Offset added before the ADC, DN.
    white_level_dn : int
        Largest ADC code (16383 for 14 bits).
    full_well_e : float, > 0
        Photosite capacity in electrons; charge beyond it is lost.
    adc_bits : int
        ADC resolution Q; quantisation is a rounding to integer DN.
    iso : int
        ISO setting the gain refers to (metadata; see `at_iso`).
    """

    gain_e_per_dn: float = 1.5
    read_noise_e: float = 4.0
    dark_current_e_per_s: float = 0.5
    black_level_dn: int = 512
    white_level_dn: int = 16383
    full_well_e: float = 40000.0
    adc_bits: int = 14
    iso: int = 400

    def __post_init__(self):
        if not self.gain_e_per_dn > 0:
            raise ValueError(f"gain_e_per_dn must be > 0 e-/DN, got {self.gain_e_per_dn}")
        if self.read_noise_e < 0 or self.dark_current_e_per_s < 0:
            raise ValueError("read_noise_e and dark_current_e_per_s must be >= 0")
        if not 0 <= self.black_level_dn < self.white_level_dn <= 2 ** self.adc_bits - 1:
            raise ValueError(
                f"need 0 <= black_level_dn ({self.black_level_dn}) < white_level_dn "
                f"({self.white_level_dn}) <= 2**adc_bits - 1 ({2 ** self.adc_bits - 1})")
        if not self.full_well_e > 0:
            raise ValueError(f"full_well_e must be > 0 electrons, got {self.full_well_e}")

    # -- derived quantities -------------------------------------------------
    @property
    def saturation_dn(self):
        """Highest mean raw value (DN, black included) before clipping: ΔVmax of eq 2.12."""
        return min(self.white_level_dn, self.black_level_dn + self.full_well_e / self.gain_e_per_dn)

    @property
    def saturation_e(self):
        """Largest signal in electrons (dark included) that is still recorded linearly."""
        return (self.saturation_dn - self.black_level_dn) * self.gain_e_per_dn

    def at_iso(self, iso):
        """The same sensor at another ISO: gain scales as 1/ISO (read noise in e- kept)."""
        return replace(self, iso=int(iso), gain_e_per_dn=self.gain_e_per_dn * self.iso / float(iso))

    def mean_dn(self, irradiance_e_per_s, t_s):
        """Expected raw value (DN, black level included, saturated), eq 2.12 without noise."""
        e = (np.asarray(irradiance_e_per_s, dtype=np.float64) + self.dark_current_e_per_s) * t_s
        return np.minimum(self.black_level_dn + e / self.gain_e_per_dn, self.saturation_dn)

    def variance_dn2(self, signal_dn, t_s=0.0):
        """Noise variance (DN²) of a raw value whose black-subtracted mean is `signal_dn`.

        Eq 2.13: signal/g (shot noise of photo- and dark electrons, since
        signal_dn = (E + D)·t/g) + read²/g² + 1/12 (uniform quantisation). `t_s`
        is unused by the formula (kept for symmetry with `mean_dn`).
        """
        s = np.maximum(np.asarray(signal_dn, dtype=np.float64), 0.0)
        g = self.gain_e_per_dn
        return s / g + (self.read_noise_e / g) ** 2 + 1.0 / 12.0

    # -- simulation ---------------------------------------------------------
    def expose(self, irradiance_rgb, t_s, rng=None):
        """Simulate one RAW exposure.

        Parameters
        ----------
        irradiance_rgb : ndarray (H, W, 3), float, >= 0
            Photo-electron rate per photosite, e-/s, per colour channel (R, G, B).
            Each RGB pixel feeds one 2×2 RGGB Bayer cell.
        t_s : float, >= 0
            Exposure time, seconds.
        rng : numpy.random.Generator or int or None

        Returns
        -------
        ndarray (2H, 2W) uint16
            RGGB mosaic in DN, black level included, clipped to [0, white_level_dn].
        """
        if t_s < 0 or not np.isfinite(t_s):
            raise ValueError(f"exposure time must be a finite number of seconds >= 0, got {t_s}")
        irr = np.asarray(irradiance_rgb, dtype=np.float64)
        if irr.ndim != 3 or irr.shape[2] != 3:
            raise ValueError(f"irradiance must have shape (H, W, 3) in e-/s, got {irr.shape}")
        return self.expose_charge(bayer_mosaic_rggb(irr) * t_s, t_s, rng)

    def expose_charge(self, photo_electrons, t_s, rng=None):
        """Simulate one RAW exposure from the expected photo-electrons per photosite.

        Use this when the light varied during the exposure (the rig simulator
        integrates LED current × time itself). `photo_electrons` is already a
        mosaic (any 2-D shape), mean electrons collected during the exposure;
        `t_s` is the exposure time in seconds (for the dark current).
        Returns a uint16 array of the same shape, DN.
        """
        rng = np.random.default_rng(rng)
        mean_e = np.asarray(photo_electrons, dtype=np.float64)
        if mean_e.ndim != 2:
            raise ValueError(f"expected a 2-D mosaic of electrons, got shape {mean_e.shape}")
        if not np.all(np.isfinite(mean_e)) or np.any(mean_e < 0):
            raise ValueError("photo-electron counts must be finite and >= 0")
        # Shot noise on photo- and dark electrons (Poisson); the well then clips.
        electrons = rng.poisson(mean_e + self.dark_current_e_per_s * t_s).astype(np.float64)
        np.minimum(electrons, self.full_well_e, out=electrons)
        if self.read_noise_e > 0:
            electrons += rng.normal(0.0, self.read_noise_e, size=electrons.shape)
        dn = self.black_level_dn + electrons / self.gain_e_per_dn
        # ADC: round to the nearest code (uniform quantisation noise, 1/12 DN²), then clip.
        np.rint(dn, out=dn)
        np.clip(dn, 0, self.white_level_dn, out=dn)
        return dn.astype(np.uint16)

    def expose_charge_rows(self, photo_electrons_rows, shape, t_s, rng=None, band_rows=256):
        """`expose_charge` of a mosaic of `shape` (H, W) given a band of rows at a time:
        `photo_electrons_rows(r0, r1)` returns rows r0..r1 of the mean electrons (r0, r1 even
        but for the last band). The noise is drawn in the order `expose_charge` draws it (all
        the shot noise, then all the read noise), so that the same `rng` gives the same
        frame; held meanwhile: the clipped electron counts (uint16 when the full well fits,
        the frame's own array). Returns the uint16 array, DN."""
        rng = np.random.default_rng(rng)
        hh, ww = (int(v) for v in shape)
        step = max(2, int(band_rows) // 2 * 2)
        counts = np.empty((hh, ww), np.uint16 if self.full_well_e <= 0xFFFF else np.uint32)
        for r0 in range(0, hh, step):
            mean_e = np.asarray(photo_electrons_rows(r0, min(r0 + step, hh)), dtype=np.float64)
            if mean_e.shape != (min(r0 + step, hh) - r0, ww):
                raise ValueError(f"rows {r0}.. of the electrons have shape {mean_e.shape}; expected "
                                 f"{(min(r0 + step, hh) - r0, ww)}")
            if not np.all(np.isfinite(mean_e)) or np.any(mean_e < 0):
                raise ValueError("photo-electron counts must be finite and >= 0")
            electrons = rng.poisson(mean_e + self.dark_current_e_per_s * t_s).astype(np.float64)
            counts[r0:r0 + step] = np.minimum(electrons, self.full_well_e)
        out = counts if counts.dtype == np.uint16 else np.empty((hh, ww), np.uint16)
        for r0 in range(0, hh, step):
            electrons = counts[r0:r0 + step].astype(np.float64)
            if self.read_noise_e > 0:
                electrons += rng.normal(0.0, self.read_noise_e, size=electrons.shape)
            dn = self.black_level_dn + electrons / self.gain_e_per_dn
            np.rint(dn, out=dn)
            np.clip(dn, 0, self.white_level_dn, out=dn)
            out[r0:r0 + step] = dn.astype(np.uint16)
        return out

    # -- profile I/O --------------------------------------------------------
    def to_profile_dict(self):
        """Plain dict for the calibration profile's `sensor` section (all fields)."""
        return asdict(self)

    @classmethod
    def from_profile_dict(cls, d):
        """Build from a profile `sensor` dict; unknown keys are ignored, missing ones default."""
        if d is None:
            return cls()
        if not isinstance(d, dict):
            d = {k: getattr(d, k) for k in cls.__dataclass_fields__ if hasattr(d, k)}
        fields = cls.__dataclass_fields__
        kw = {k: v for k, v in d.items() if k in fields}
        for k in ("black_level_dn", "white_level_dn", "adc_bits", "iso"):
            if k in kw:
                kw[k] = int(round(float(kw[k])))
        return cls(**kw)


DEFAULT_SENSOR = SensorModel()
