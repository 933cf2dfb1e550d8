"""Stray light added to each view's camera electrons [3, H, W] (after the kernels, binning and cos⁴; before
the mosaic and the noise), in the order light meets it; e is the view's electrons, w_ck the camera's
electrons per unit band radiance (sensor.band_electron_weights), g_k the view's band gains (T · τ · (1 − o)),
C the cos⁴ map:

a. room light on the monitor's screen (monitor scenes): a uniform radiance L = R E / π (the ambient term
   of the ambient contrast ratio, Chen, Tan & Wu, Opt. Express 25, 33643, 2017) with the room illuminant's
   spectrum, seen through each view like the screen's own light: e += C · Σ_k w_ck g_k L_k. The ground truth
   sees it too (same room, through glass, l.235).
d. haze of the display stack: e ← (1 − h) e + h (e ⊗ ρ_tail(θ ≥ 2.5°)) (SRUDC's y = t·(x⊗k) + (1 − t)·A,
   Song et al. ICCV 2023, with the veil's shape from the scatter tail instead of the frame mean); the
   ground truth's glass has none.
e. the driven display's own light toward the lens (display views only): a uniform radiance of luminance
   L_d (D65 white) at the lens, totally defocused: e += C · Σ_k w_ck g⁰_k L_d,k (g⁰: the bare lens's gains).
b. ghost: R_lens of the light at the lens reflects off its front face, R_under of that off the display's
   (or the glass's) underside, back into the lens: e += R_lens R_under (e ⊗ disc). Seen from the lens it
   comes from a virtual source z_g ≈ 2 g + R_c / 2 away (g the gap, R_c the front face's radius: a convex
   mirror), so its blur on the sensor is D · s / z_g (D the aperture, s ≈ f); a flat face gives a sharp,
   coincident copy (a gain). The default 2000 µm is z_g ≈ 10 mm with the paper's 3333 µm, 6 mm lens.
c. the lens's veiling glare: e ← (1 − v) e + v (e ⊗ ρ_tail(θ ≥ 1°)), every view, the ground truth too
   (the paper's ground truth was taken through the same lens, l.235).

ρ are spreads of optics.stray.spread; light they send beyond the frame leaves it. Each view's record gives
every effect's fraction and the share of the view's light it added or moved.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from udc_render.content.spectra import band_means, illuminant, scaled_to_luminance
from udc_render.optics.stray.settings import StrayLight
from udc_render.optics.stray.spread import Spread, convolve
from udc_render.sensor import SensorConfig, band_electron_weights, cos4_map

EMISSION_WHITE = "D65"


@dataclass(frozen=True)
class StrayContext:
    """What the stray light of one synthesis needs: the band edges, the sensor (exposure, pitch, focal length,
    cos⁴), whether the scene is a monitor (room light on its screen) and the bare lens's band gains g⁰."""
    edges_nm: np.ndarray
    sensor: SensorConfig
    monitor: bool
    glass_gains: np.ndarray


def uniform_electrons(luminance_cd_m2: float, spectrum: str, gains: np.ndarray, shape: tuple[int, int],
                      ctx: StrayContext) -> np.ndarray:
    """Electrons [3, H, W] of a uniform radiance of the given luminance and illuminant spectrum through
    band gains: C · Σ_k w_ck g_k L_k."""
    L = band_means(scaled_to_luminance(illuminant(spectrum), luminance_cd_m2), ctx.edges_nm)
    per_channel = band_electron_weights(ctx.edges_nm, ctx.sensor) @ (np.asarray(gains, float) * L)
    s = ctx.sensor
    c4 = cos4_map(*shape, s.pitch_um, s.focal_length_um) if s.cos4_falloff else np.ones(shape)
    return per_channel[:, None, None] * c4[None]


def _tail(e: np.ndarray, share: float, inner_deg: float, ctx: StrayContext) -> tuple[np.ndarray, dict]:
    veil, landed, b = convolve(e, Spread("tail", ctx.sensor.focal_length_um, inner_deg=inner_deg), ctx.sensor.pitch_um)
    return (1.0 - share) * e + share * veil, {"moved_share": share, "landed_share_of_moved": landed,
                                              "inner_deg": inner_deg, "coarse_px": b}


def apply_view(stray: StrayLight, e: np.ndarray, display: str, glass: bool, gains, ctx: StrayContext):
    """(electrons with the stray light, record) of one view: display its name ('glass' for the ground
    truth), glass whether it is the glass (no emission), gains its band gains (module doc, a → c)."""
    total = float(e.sum())

    def share(x) -> float:
        return float(x.sum()) / total if total > 0 else 0.0
    rec: dict = {}
    if stray.room_on:
        if ctx.monitor:
            lum = stray.screen_reflectance * stray.room_illuminance_lux / math.pi
            ped = uniform_electrons(lum, stray.room_illuminant, gains, e.shape[1:], ctx)
            e = e + ped
            rec["room"] = {"screen_luminance_cd_m2": lum, "added_share": share(ped),
                           "mean_e": ped.mean(axis=(1, 2)).tolist()}
        else:
            rec["room"] = "not applied: only a monitor scene's screen reflects the room (3D scenes render theirs)"
    h = stray.haze_of(display)
    if h > 0:
        e, rec["haze"] = _tail(e, h, stray.haze_inner_deg, ctx)
    if stray.emission_on and not glass:
        em = uniform_electrons(stray.display_luminance_cd_m2, EMISSION_WHITE, ctx.glass_gains, e.shape[1:], ctx)
        e = e + em
        rec["emission"] = {"luminance_cd_m2": stray.display_luminance_cd_m2, "added_share": share(em),
                           "mean_e": em.mean(axis=(1, 2)).tolist()}
    r = stray.lens_reflectance * stray.underside_of(display)
    if r > 0:
        ghost, landed, b = convolve(e, Spread("disc", ctx.sensor.focal_length_um, radius_um=stray.ghost_blur_um / 2),
                                    ctx.sensor.pitch_um)
        e = e + r * ghost
        rec["ghost"] = {"reflectance_product": r, "added_share": share(r * ghost), "landed_share": landed,
                        "blur_um": stray.ghost_blur_um, "coarse_px": b}
    if stray.lens_glare > 0:
        e, rec["glare"] = _tail(e, stray.lens_glare, stray.glare_inner_deg, ctx)
    return e, rec


def stray_electrons(stray: StrayLight, electrons: dict, ctx: StrayContext, glass_names=()) -> dict:
    """{view: (electrons, record + 'stray_light')} for views.layered_electrons' output ('gt': the glass)."""
    out = {}
    for name, (e, rec) in electrons.items():
        display = "glass" if name == "gt" else name
        e2, r = apply_view(stray, e, display, name == "gt" or name in glass_names, rec["gains"], ctx)
        out[name] = (e2, {**rec, "stray_light": r})
    return out


def synthesis_stray_light(stray: StrayLight, electrons: dict, band_image, sensor: SensorConfig, form: str,
                          glass_names=()) -> tuple[dict, dict]:
    """(electrons with the stray light, the synth.json record) of one synthesis: the spectral form only (the
    per-channel form is the paper's y = γ x ⊗ k + n, without stray light: recorded as not applied)."""
    record = {"settings": stray.describe(), "applied": form == "spectral" and not stray.is_off()}
    if not record["applied"]:
        if form != "spectral" and not stray.is_off():
            record["note"] = "not applied: the per-channel form (the paper's y = γ x ⊗ k + n) has no stray light"
        return {name: (e, {**rec, "stray_light": {}}) for name, (e, rec) in electrons.items()}, record
    ctx = StrayContext(np.asarray(band_image.edges_nm, float), sensor, band_image.primaries_matrix is not None,
                       np.asarray(electrons["gt"][1]["gains"], float))
    return stray_electrons(stray, electrons, ctx, glass_names), record
