"""The calibration wizard's step sequence (`facette calibrate`): steps, checks, profile.

Steps, in order (each guided: place the target, press the button / Enter):

1. ``noise``     camera noise (photon transfer): dark pairs with the lens cap on,
                 flat pairs on the Spectralon under one LED (facette.hdr.estimate_sensor_ptc);
2. ``mirror``    light directions from the chrome sphere (and the pixel pitch from its size);
3. ``positions`` (optional) the sphere at a second place: LED positions (near-light model);
4. ``matte``     matte-sphere directions as a cross-check of the mirror sphere;
5. ``spectralon`` relative LED intensities per channel and the flat field;
6. ``gains``     per-LED current gains written to the device's calibration store,
                 checked after a reboot, then verified by a second Spectralon capture.

Each capture is checked (target found, exposure usable, residuals within
tolerance); a failed check raises `WizardError` with what was wrong and what to do.
The result is a versioned, checksummed profile (`facette.calib.save`), the
previous one kept. `check_profile` re-measures directions and intensities and
reports the drift against an existing profile.

The station (`facette.wizard.station.RigStation`) is what captures: a `facette.scan.Rig` (a real rig,
or ``facette.connect("sim")`` whose simulator shows each target by itself).
"""
from __future__ import annotations

import dataclasses
import datetime as _dt
import time
from pathlib import Path

import numpy as np

from facette._data import profiles_dir
from facette.calib.checks import Tolerances, WizardError, angle_deg, check_exposure
from facette.calib.lp import write_profile_lp
from facette.calib.matte_sphere import matte_sphere_directions
from facette.calib.mirror_sphere import (directions_from_origin, light_positions_from_rays,
                                         mirror_sphere_directions, sphere_rays)
from facette.calib.profile import Lights, Profile, nominal_light_directions, save
from facette.calib.spectralon import flat_field, led_current_gains, spectralon_intensities, target_mask
from facette.calib.targets import channel_reflectance, load_target
from facette.camera.sensor import SENSOR_KEYS, SensorModel
from facette.hdr import estimate_sensor_ptc_files
from facette.wizard.station import INSTRUCTIONS

__all__ = ["Wizard", "STEPS", "BRACKETS_US", "DARK_US", "FLAT_US"]

STEPS = ("noise", "mirror", "positions", "matte", "spectralon", "gains")
# Exposure brackets per target (µs), at the wizard's LED current: the sphere's
# highlight is ~100× brighter than the Spectralon, hence its short end.
BRACKETS_US = {
    "spectralon": (1_000_000, 250_000, 60_000),
    "mirror_sphere": (1_000_000, 100_000, 10_000, 1_000),
    "matte_sphere": (1_000_000, 250_000, 60_000),
}
DARK_US = (100_000, 100_000, 2_000_000, 2_000_000)
FLAT_US = (10_000, 30_000, 100_000, 300_000, 600_000, 1_200_000, 2_400_000, 4_000_000)



class Wizard:
    """Runs the calibration steps on a station and builds the profile.

    station : RigStation (or any object with the same methods)
    out : print-like callable for the transcript
    steps : which of STEPS to run ("positions" only when asked)
    base : a Profile whose values are kept for the steps not run (default nominal)
    """

    def __init__(self, station, out=print, steps=None, base=None, tol=None, exposures=None,
                 mirror_spec="mirror-sphere", matte_spec="matte-sphere", certificate="spectralon-99",
                 led_distance_mm=None):
        self.st = station
        self.out = out
        self.steps = [s for s in STEPS if s != "positions"] if steps is None else list(steps)
        unknown = set(self.steps) - set(STEPS)
        if unknown:
            raise ValueError(f"unknown steps {sorted(unknown)}; choose from {', '.join(STEPS)}")
        self.tol = tol or Tolerances()
        self.exposures = exposures
        self.mirror = load_target(mirror_spec)
        self.matte = load_target(matte_spec)
        self.cert = load_target(certificate)
        m = station.n_leds
        if base is not None and len(base.lights) != m:
            raise ValueError(f"the base profile has {len(base.lights)} lights, the rig {m}")
        self.directions = base.lights.directions.copy() if base is not None else nominal_light_directions()[:m]
        self.intensities = base.lights.intensities.copy() if base is not None else np.ones((m, 3))
        self.positions = None if base is None else base.lights.positions_mm
        self.sensor = None if base is None else base.sensor
        self.flat = None if base is None else base.flat_field
        self.radiometric_scale = None if base is None else base.radiometric_scale
        self.gains = None if base is None else base.led_gains
        self.pitch = None if base is None else base.pixel_pitch_mm
        self.base = base
        self.size = None   # (w, h) of the HDR images of this calibration's captures
        self.led_distance_mm = led_distance_mm
        if self.sensor is not None:
            self._use_sensor(self.sensor)
        self.history = []
        self.figures = {}
        self.circle = None

    # -- helpers -----------------------------------------------------------------------------
    def _use_sensor(self, sensor):
        """Merge the captures with this noise model (a profile `sensor` dict)."""
        self.st.sensor = SensorModel.from_profile_dict(sensor)
        self.st.full_scale_dn = float(sensor["white_level_dn"] - sensor["black_level_dn"])

    def _say(self, text=""):
        self.out(text)

    def _note(self, text):
        self.history.append(text)
        self._say(f"  ✓ {text}")

    def _bracket(self, kind):
        return tuple(self.exposures) if self.exposures else BRACKETS_US[kind]

    def _hdr(self, kind, name, current="measured", mask=None):
        ex = self._bracket(kind)
        images, d = self.st.capture(name, ex, current=current)
        size = (images.shape[2], images.shape[1])
        if self.size is not None and size != self.size:
            raise WizardError(f"{name}: images of {size[0]}×{size[1]} px, the calibration so far was "
                              f"measured at {self.size[0]}×{self.size[1]} px: keep the camera at one "
                              "resolution for the whole calibration")
        self.size = size
        # a clipped highlight biases its centroid: on the mirror sphere no pixel may saturate
        tol = dataclasses.replace(self.tol, saturated_fraction=0.0) if kind == "mirror_sphere" else self.tol
        level, sat = check_exposure(images, max(ex), min(ex), self.st.current_mA, self.st.full_scale_dn,
                                    kind.replace("_", " "), mask=mask, tol=tol)
        return images, level

    # -- steps -----------------------------------------------------------------------------
    def step_noise(self):
        self._say("Step: camera noise (photon transfer curve, thesis eq 2.12–2.13)")
        self.st.place("lens_cap")
        darks = self.st.capture_raw("dark", DARK_US)
        self.st.place("spectralon")
        flats = self.st.capture_raw("flat", tuple(t for t in FLAT_US for _ in range(2)), light=0)
        try:
            ptc = estimate_sensor_ptc_files(darks, flats)
        except ValueError as exc:
            raise WizardError(f"camera noise: the photon transfer fit failed ({exc}); check that the "
                              "lens cap was on for the dark frames and the Spectralon lit for the flats")
        if ptc.fit_rms_rel > self.tol.ptc_fit:
            raise WizardError(f"camera noise: the photon transfer curve is not a line (rms {100 * ptc.fit_rms_rel:.0f} % "
                              f"> {100 * self.tol.ptc_fit:.0f} %): light leaking in, or a flickering LED; "
                              "close the enclosure and run the step again")
        d = ptc.to_profile_dict()
        self.sensor = {k: d[k] for k in SENSOR_KEYS} | ({"full_well_e": d["full_well_e"]} if "full_well_e" in d else {})
        self._use_sensor(self.sensor)
        self.figures["sensor"] = self.sensor
        self._note(f"sensor: gain {d['gain_e_per_dn']:.3f} e-/DN, read noise {d['read_noise_e']:.2f} e-, "
                   f"dark current {d['dark_current_e_per_s']:.2f} e-/s, black {d['black_level_dn']} DN, "
                   f"white {d['white_level_dn']} DN (PTC fit rms {100 * ptc.fit_rms_rel:.1f} %)")

    def _mirror_capture(self, name, **place_kw):
        images, _ = self._hdr("mirror_sphere", name)
        try:
            dirs, circle, hls = mirror_sphere_directions(images)
        except ValueError as exc:
            raise WizardError(f"mirror sphere: not found ({exc}). Place the chrome sphere on its collar "
                              "at the centre of the field, on the grey card, then run the step again.")
        if circle.rms > self.tol.outline_rms_px:
            raise WizardError(f"mirror sphere: its outline is not a circle (rms {circle.rms:.2f} px > "
                              f"{self.tol.outline_rms_px} px): it is cut by the frame, dirty, or not a "
                              "sphere; centre it and clean it, then run the step again")
        return images, dirs, circle, hls

    def step_mirror(self):
        self._say("Step: light directions from the chrome sphere (l = 2(n·v)n − v)")
        self.st.place("mirror_sphere", radius_mm=self.mirror["diameter_mm"] / 2)
        images, dirs, circle, hls = self._mirror_capture("mirror")
        nominal = nominal_light_directions()[:len(dirs)]
        off = angle_deg(dirs, nominal)
        bad = np.flatnonzero(off > self.tol.nominal_deg)
        if bad.size:
            raise WizardError(f"mirror sphere: LED(s) {bad.tolist()} are {np.round(off[bad], 1).tolist()}° "
                              f"from their nominal directions (> {self.tol.nominal_deg}°): is each LED wired "
                              "to its channel? Fix the wiring, then run the step again.")
        self.pitch = self.mirror["diameter_mm"] / 2 / circle.r
        if self.led_distance_mm:
            # seen from the field's origin rather than from the highlight (parallax)
            o, l = sphere_rays(circle, hls, images.shape[1:3], self.pitch,
                               sphere_radius_mm=self.mirror["diameter_mm"] / 2)
            dirs = directions_from_origin(o, l, self.led_distance_mm)
            off = angle_deg(dirs, nominal)
            self._note(f"directions seen from the field's origin, LEDs at {self.led_distance_mm:.0f} mm")
        self.directions, self.circle = dirs, circle
        if self.led_distance_mm:
            # near-light model at the rig's nominal distance (the positions step refines it)
            self.positions = dirs * float(self.led_distance_mm)
        # the centroid's precision: a highlight to σ px on R px ≈ 1.44°·σ·(100/R) (REFERENCE §6)
        self.figures["mirror"] = {"circle": dataclasses.asdict(circle), "directions": dirs.tolist(),
                                  "from_nominal_deg": off.tolist(), "pixel_pitch_mm": self.pitch}
        self._note(f"sphere: centre ({circle.cx:.2f}, {circle.cy:.2f}) px, radius {circle.r:.2f} px "
                   f"(outline rms {circle.rms:.3f} px) → pixel pitch {self.pitch:.4f} mm")
        for i, d in enumerate(dirs):
            th, ph = np.degrees(np.arccos(d[2])), np.degrees(np.arctan2(d[1], d[0])) % 360
            self._say(f"    LED {i:2d}: θ {th:6.2f}°  φ {ph:7.2f}°  ({off[i]:.2f}° from nominal)"
                      + ("  [highlight saturated]" if hls[i].saturated else ""))

    def step_positions(self, shift_mm=20.0):
        self._say("Step: LED positions from two placements of the chrome sphere (near-light model)")
        if self.circle is None:
            raise WizardError("LED positions need the mirror step first (run it in the same session)")
        r_mm = self.mirror["diameter_mm"] / 2
        rays = []
        for k, dx in enumerate((-shift_mm, shift_mm)):
            self.st.place("mirror_sphere#%d" % k, INSTRUCTIONS["mirror_sphere_2"].format(dx=dx),
                          radius_mm=r_mm, center_mm=(dx, 0.0))
            images, dirs, circle, hls = self._mirror_capture(f"mirror-{k}")
            rays.append(sphere_rays(circle, hls, images.shape[1:3], self.pitch, sphere_radius_mm=r_mm))
        o = np.array([r[0] for r in rays])
        d = np.array([r[1] for r in rays])
        try:
            pos, rms = light_positions_from_rays(o, d)
        except ValueError as exc:
            raise WizardError(f"LED positions: {exc}")
        dist = np.linalg.norm(pos, axis=1)
        self.figures["positions"] = {"positions_mm": pos.tolist(), "ray_rms_mm": rms.tolist()}
        if np.any(dist > 20_000) or np.any(pos[:, 2] <= 0):
            self._note("LED positions: the rays are parallel within their noise (LEDs effectively "
                       f"distant, median distance {np.median(dist):.0f} mm): positions not stored")
            return
        self.positions = pos
        self.directions = pos / dist[:, None]
        self._note(f"LED positions: distance {dist.min():.0f}–{dist.max():.0f} mm, ray rms "
                   f"{rms.max():.2f} mm")

    def step_matte(self):
        self._say("Step: matte sphere (Lambertian fit), a cross-check of the directions")
        self.st.place("matte_sphere", radius_mm=self.matte["diameter_mm"] / 2)
        images, _ = self._hdr("matte_sphere", "matte")
        try:
            dirs, inten, resid, circle = matte_sphere_directions(images)
        except ValueError as exc:
            raise WizardError(f"matte sphere: not found ({exc}). Place the matte sphere at the centre "
                              "of the field, then run the step again.")
        if self.led_distance_mm and self.pitch:
            # seen from the field's origin, not from the sphere's centre (parallax, as for the mirror)
            h, w = images.shape[1:3]
            r_mm = self.matte["diameter_mm"] / 2
            c = np.array([(circle.cx - (w - 1) / 2) * self.pitch, ((h - 1) / 2 - circle.cy) * self.pitch, r_mm])
            dirs = directions_from_origin(np.tile(c, (len(dirs), 1)), dirs, self.led_distance_mm)
        diff = angle_deg(dirs, self.directions)
        self.figures["matte"] = {"directions": dirs.tolist(), "vs_mirror_deg": diff.tolist(),
                                 "residual_rel": resid.tolist()}
        worst = int(np.argmax(diff))
        msg = (f"matte vs mirror: mean {diff.mean():.2f}°, worst {diff[worst]:.2f}° (LED {worst}); "
               f"Lambert fit residual ≤ {100 * resid.max():.1f} %")
        if diff[worst] > self.tol.matte_vs_mirror_deg:
            self.history.append("WARNING " + msg)
            self._say(f"  ! {msg}: above {self.tol.matte_vs_mirror_deg}°; the mirror sphere's directions "
                      "are kept; re-seat both spheres and re-run if this persists")
        else:
            self._note(msg)

    def _spectralon(self, name, current="measured"):
        images, _ = self._hdr("spectralon", name, current=current)
        mask = target_mask(images)
        cover = mask.mean() / (1 - 2 * 0.05) ** 2
        if cover < self.tol.min_coverage:
            raise WizardError(f"Spectralon: it fills only {100 * cover:.0f} % of the field (need "
                              f"{100 * self.tol.min_coverage:.0f} %): lay it flat under the camera, "
                              "filling the field, then run the step again")
        rho = channel_reflectance(self.cert)
        res = spectralon_intensities(images, self.directions, rho, mask=mask,
                                     positions_mm=self.positions,
                                     pixel_pitch_mm=self.pitch if self.positions is not None else None)
        return images, mask, res, rho

    def step_spectralon(self):
        self._say("Step: Spectralon — LED intensities per channel and flat field (thesis §4.3.2)")
        self.st.place("spectralon")
        images, mask, res, rho = self._spectralon("spectralon")
        ff = flat_field(images, self.directions, mask=mask, positions_mm=self.positions,
                        pixel_pitch_mm=self.pitch if self.positions is not None else None)
        # what the flat field leaves: each LED's image divided by its geometry and F
        resid = spectralon_intensities(images, self.directions, rho, mask=mask, flat=ff,
                                       positions_mm=self.positions,
                                       pixel_pitch_mm=self.pitch if self.positions is not None else None)
        self.intensities, self.flat = res.intensities, ff
        # image units per unit irradiance of a light of intensity 1: what turns the pipeline's
        # images into radiance factors, so that K_d and the albedo are reflectances
        self.radiometric_scale = (res.absolute / res.intensities).mean(axis=0).tolist()
        self.figures["spectralon"] = {"intensities": res.intensities.tolist(),
                                      "nonuniformity": resid.nonuniformity.tolist(),
                                      "reflectance_rgb": rho.tolist()}
        g = res.intensities[:, 1]
        self._note(f"certificate {self.cert.get('serial', '?')}: reflectance R,G,B "
                   f"{rho[0]:.4f} {rho[1]:.4f} {rho[2]:.4f}")
        self._note(f"LED intensities (green, mean 1): {g.min():.3f}–{g.max():.3f} "
                   f"(spread {100 * (g.max() / g.min() - 1):.1f} %)")
        for i, I in enumerate(res.intensities):
            self._say(f"    LED {i:2d}: R {I[0]:.4f}  G {I[1]:.4f}  B {I[2]:.4f}   "
                      f"residual {100 * resid.nonuniformity[i]:.2f} %")
        sc = self.radiometric_scale
        self._note(f"radiometric scale R,G,B {sc[0]:.4g} {sc[1]:.4g} {sc[2]:.4g} (HDR units per unit irradiance)")
        self._note(f"flat field: {ff.shape[1]}×{ff.shape[0]} px, range {ff.min():.3f}–{ff.max():.3f}")
        worst = float(resid.nonuniformity.max())
        if worst > self.tol.nonuniformity:
            raise WizardError(f"Spectralon: after the flat field, an LED's image still varies by "
                              f"{100 * worst:.1f} % (> {100 * self.tol.nonuniformity:.0f} %): the target is "
                              "tilted, dirty or in a shadow; lay it flat and clean, then run the step again")

    def step_gains(self):
        self._say("Step: equalise the LEDs — current gains in the device's calibration store")
        g_now = self.st.gains()
        m = len(self.intensities)
        try:
            gains = led_current_gains(self.intensities, channel=1, target="lowest", limits=(0.5, 2.0))
        except ValueError as exc:
            raise WizardError(f"LED gains: {exc}")
        full = list(g_now)
        full[:m] = [float(round(g, 4)) for g in gains]
        self.st.set_gains(full)
        boot = self.st.reboot()
        back = self.st.gains()
        if not np.allclose(back[:m], full[:m], atol=1.5e-4):
            raise WizardError("LED gains: after a reboot the device reads back "
                              f"{np.round(back[:m], 4).tolist()} instead of {np.round(full[:m], 4).tolist()}: "
                              "its calibration store did not keep them; check `facette device faults` "
                              "(CAL_INVALID) and run the step again")
        self._note(f"gains {np.round(gains, 4).tolist()} written, kept across a reboot (boot {boot})")
        # verify: per *set* mA, the LEDs should now give the same light
        self.st.place("spectralon", "Keep the Spectralon in place (verification capture).")
        _, _, res, _ = self._spectralon("spectralon-verify", current="set")
        before = self.intensities[:, 1]
        after = res.intensities[:, 1]
        sb, sa = before.max() / before.min() - 1, after.max() / after.min() - 1
        self.gains = full[:m]
        self.figures["gains"] = {"gains": list(gains), "spread_before": float(sb), "spread_after": float(sa)}
        if sa > self.tol.gain_spread:
            raise WizardError(f"LED gains: after equalisation the LEDs still differ by {100 * sa:.1f} % "
                              f"(> {100 * self.tol.gain_spread:.0f} %): an LED is not linear in current "
                              "or its current sense is off; check `facette device` measurements")
        self._note(f"verified on a second Spectralon capture: LED spread {100 * sb:.1f} % → {100 * sa:.2f} %")

    # -- the whole run ---------------------------------------------------------------------
    def run(self, folder=None, rig_name=None):
        """Run the steps, then write the profile into `folder` (default
        calibration/profiles/<rig>/). Returns (Profile, path)."""
        t0 = time.perf_counter()
        rig_name = rig_name or self.st.rig_name
        self._say(f"facette calibrate — rig {rig_name}, {self.st.n_leds} LEDs, steps: {', '.join(self.steps)}")
        order = {"noise": self.step_noise, "mirror": self.step_mirror, "positions": self.step_positions,
                 "matte": self.step_matte, "spectralon": self.step_spectralon, "gains": self.step_gains}
        try:
            for k, name in enumerate(s for s in STEPS if s in self.steps):
                self._say()
                self._say(f"[{k + 1}/{len(self.steps)}] " + name)
                order[name]()
        finally:
            self.st.restore()
        self._base_at_size()
        lights = Lights(self.directions, self.intensities, self.positions)
        now = _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds")
        prof = Profile(rig=rig_name, lights=lights, created=now, pixel_pitch_mm=self.pitch,
                       sensor=self.sensor, flat_field=self.flat, led_gains=self.gains,
                       radiometric_scale=self.radiometric_scale,
                       image_size_px=self.size, binning=2 if self.size is not None else None,
                       history=[f"{now} facette calibrate: {', '.join(self.steps)}"] + self.history)
        folder = Path(folder) if folder else profiles_dir() / rig_name
        path = save(prof, folder)
        # the same directions for the RTI world (RTIBuilder, relight): one .lp per profile
        write_profile_lp(prof, folder / f"lights-{prof.id}.lp")
        self._say()
        self._say(f"profile {prof.id} written to {path} (sha256 {prof.sha256[:12]}…; previous kept "
                  f"beside it) in {time.perf_counter() - t0:.1f} s")
        return prof, path

    def _base_at_size(self):
        """Values kept from a base profile measured at another image size: scaled to this one."""
        base = self.base
        if base is None:
            return
        if self.size is None or base.measured_size() in (None, self.size):
            self.size = self.size or base.measured_size()
            return
        at = base.at_size(self.size)
        if self.flat is base.flat_field:
            self.flat = at.flat_field
        if self.pitch == base.pixel_pitch_mm:
            self.pitch = at.pixel_pitch_mm
        self._note(at.note)

    def check(self, profile):
        """Re-measure directions (mirror sphere) and intensities (Spectralon) and report the
        drift against `profile`. Returns (ok, report dict)."""
        self._say(f"facette calibrate --check {profile.id}")
        if profile.sensor is not None:
            self._use_sensor(profile.sensor)
        self.positions, self.pitch = profile.lights.positions_mm, profile.pixel_pitch_mm
        try:
            self._say()
            self.st.place("mirror_sphere", radius_mm=self.mirror["diameter_mm"] / 2)
            images, dirs, circle, hls = self._mirror_capture("check-mirror")
            if profile.lights.positions_mm is not None:
                # the profile's LEDs are near: compare directions seen from the field's origin
                dist = float(np.mean(np.linalg.norm(profile.lights.positions_mm, axis=1)))
                pitch = self.pitch or self.mirror["diameter_mm"] / 2 / circle.r
                o, l = sphere_rays(circle, hls, images.shape[1:3], pitch,
                                   sphere_radius_mm=self.mirror["diameter_mm"] / 2)
                dirs = directions_from_origin(o, l, self.led_distance_mm or dist)
            self.directions = dirs
            self.st.place("spectralon")
            _, _, res, _ = self._spectralon("check-spectralon")
        finally:
            self.st.restore()
        dd = angle_deg(dirs, profile.lights.directions)
        di = res.intensities / profile.lights.intensities - 1
        worst_i = np.abs(di).max(axis=1)
        self._say("    LED   direction drift   intensity drift (R, G, B)")
        for i in range(len(dd)):
            flag = " !" if dd[i] > self.tol.drift_deg or worst_i[i] > self.tol.drift_intensity else ""
            self._say(f"    {i:3d}   {dd[i]:8.2f}°        "
                      + "  ".join(f"{100 * v:+6.2f} %" for v in di[i]) + flag)
        ok = bool(dd.max() <= self.tol.drift_deg and worst_i.max() <= self.tol.drift_intensity)
        if profile.led_gains is not None:
            now = np.asarray(self.st.gains()[:len(profile.led_gains)])
            if not np.allclose(now, profile.led_gains, atol=1.5e-4):
                # intensities are per measured mA, so the profile still holds; the LEDs are not equal
                self._say(f"  ! the device's calibration store holds gains {np.round(now, 4).tolist()}, not the "
                          "profile's: the device was recalibrated or replaced; run `facette calibrate --only gains`")
        verdict = ("within tolerance" if ok else
                   f"DRIFTED beyond {self.tol.drift_deg}° / {100 * self.tol.drift_intensity:.0f} %: recalibrate "
                   "(facette calibrate)")
        self._say(f"  drift: directions ≤ {dd.max():.2f}°, intensities ≤ {100 * worst_i.max():.2f} % — {verdict}")
        return ok, {"direction_deg": dd.tolist(), "intensity_rel": di.tolist(), "ok": ok}
