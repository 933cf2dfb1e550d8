"""A CFA mosaic's sites balanced by the orders themselves: no camera's response assumed.

At the laser's line each colour's sites read the same irradiance times their response g_c. The matched filter
restricted to one colour's sites (photometry.measure, `sites`) estimates every order's power P_c = g_c P
whatever the spot's sampling phase: its template integrates the Airy pattern on exactly the pixels it uses. On
the exposures balanced by a guess ĝ, P_c / P_ref = (g_c / ĝ_c) / (g_ref / ĝ_ref) for the reference colour (the
guess's strongest), estimated by the median of the orders' ratios over the orders above SNR_MIN in both colours,
in every exposure, with every unsaturated pixel (a hot pixel spoils one order's ratio, which the median leaves
out), its σ from their MAD:
    k_c = median(P_c / P_ref),   σ(k_c) = 1.2533 · 1.4826 MAD / √n,
and the measured response g_c ∝ ĝ_c k_c (relative to the strongest). A least-squares slope on P_ref (noisy
too) came out 1–2 % low (its errors-in-variables bias), the ratio of the sums 3 % low on a Nikon's green (the
orders beside a saturated one hold its wings, which each colour's filter sees on other pixels).

The lattice is found on the balanced image, whose centroids a wrong balance pulls toward the brighter sites, so
the passes repeat (balance, lattice, ratios) until the gains move by less than half their σ (converged). The
first guess is each colour's mean signal per site in the dimmest exposure (first_guess), not a camera's response.
A colour with fewer than MIN_ORDERS such orders keeps the guess (noted). Measured (tests/udc_render/
test_fit_cfa.py): a 650 nm pentile through a Sigma SDMerill's sites (G 0.835, B 0.511 of R) in a 255-px window
came back within 0.9 % and 1.1 % (0.7 σ, 0.6 σ) in 3 passes; in a 191-px window (fewer orders) B stayed 3.6 % low
(3.2 σ) after 6. Started from the Nikon's response (G 0.079) instead, the 191-px case moved 0.32 → 0.44 in B in
three passes: the first guess matters where the orders are few.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from udc_render.fit.hdr import Plane, merge_psf
from udc_render.fit.inputs import COLOURS, border, saturated
from udc_render.fit.photometry import Optics, lattice_orders, measure

SNR_MIN = 10.0
MIN_ORDERS = 3
MAX_PASSES = 6  # balance, lattice, ratios again until the gains move by less than half their σ (or 1e-3)


@dataclass(frozen=True)
class SiteGains:
    """The colours' measured response (R, G, B) relative to the strongest, its σ, the guess it corrected (in
    fit.json --camera's, for comparison), the orders each ratio used (0: not measured, the guess kept), passes."""
    gains: tuple
    sigma: tuple
    guess: tuple
    orders: tuple
    passes: int = 1

    def record(self) -> dict:
        return {"measured": list(self.gains), "sigma": list(self.sigma), "camera_response": list(self.guess),
                "orders_used": list(self.orders), "passes": self.passes,
                "how": "matched filter on each colour's sites (fit.cfa)"}

    def note(self) -> str:

        def fmt(v):
            return "/".join(f"{x:.3f}" for x in v)
        kept = [COLOURS[c] for c, n in enumerate(self.orders) if n == 0]
        return (f"CFA sites balanced by the orders: R/G/B response {fmt(self.gains)} ± {fmt(self.sigma)} (fit.json: "
                "psf.cfa_response)" + (f"; {', '.join(kept)} kept at the guess (too few orders)" if kept else ""))


def _colour_powers(plane: Plane, colours: np.ndarray, where, optics: Optics) -> tuple[np.ndarray, np.ndarray]:
    """P [3, E·N] and σ [3, E·N] of every order in every exposure on each colour's sites (inf: not measured);
    where: psf_fit.first_lattice's (window, lattice, index basis, aperture radius)."""
    window, lattice, m, radius_px = where
    index = lattice_orders(lattice, m, window.half, radius_px)
    xy, col = lattice.points(index), window.crop(colours)
    power, sigma = np.zeros((3, 0)), np.zeros((3, 0))
    for e in plane.exposures:
        rows = [measure(window.crop(e.d), window.crop(e.var), ~window.crop(e.saturated), xy, index, radius_px,
                        optics.lens, optics.wavelength_nm, optics.pixel_um, sites=col == k) for k in range(3)]
        power = np.concatenate([power, np.stack([r.power for r in rows])], axis=1)
        sigma = np.concatenate([sigma, np.stack([np.where(r.measured, r.sigma, np.inf) for r in rows])], axis=1)
    return power, sigma


def site_gains(plane: Plane, colours: np.ndarray, where, optics: Optics) -> SiteGains:
    """The colours' response measured from the orders where psf_fit.first_lattice puts them (`where`; module
    doc); colours: the frame's colour map [H, W] (inputs.Frame.colour_map)."""
    guess = np.asarray(plane.colour_gain, float)
    power, sigma = _colour_powers(plane, colours, where, optics)
    ref = int(np.argmax(guess))
    ratio, ratio_sigma, used = np.ones(3), np.zeros(3), [0, 0, 0]
    for k in range(3):
        ok = (power[k] > SNR_MIN * sigma[k]) & (power[ref] > SNR_MIN * sigma[ref])
        if k == ref or ok.sum() < MIN_ORDERS:
            used[k] = int(ok.sum()) if k == ref else 0
            continue
        r = power[k][ok] / power[ref][ok]
        ratio[k], used[k] = np.median(r), int(ok.sum())
        ratio_sigma[k] = 1.2533 * 1.4826 * np.median(np.abs(r - ratio[k])) / np.sqrt(used[k])
    gains = guess * ratio
    top = gains.max()
    return SiteGains(tuple(float(g) for g in gains / top), tuple(float(s) for s in guess * ratio_sigma / top),
                     tuple(float(g) for g in guess), tuple(used))


def first_guess(frames) -> np.ndarray:
    """(R, G, B) relative response from the dimmest exposure alone: each colour's mean signal per unsaturated site
    above its border's median. Biased by the sampling phases of ~1-px orders; the passes take that off."""
    frame = min(frames, key=lambda f: float(np.sum(f.above_black())))
    d, colours = frame.above_black(), frame.colour_map()
    edge, sat = border(d.shape), saturated(frame, frame.dn)
    means = np.array([np.mean(d[(colours == k) & ~sat & ~edge] - np.median(d[(colours == k) & edge]))
                      for k in range(3)])
    return np.clip(means / means.max(), 1e-3, 1.0)


def converged(frames, colours, wavelength_nm: float, camera: str, dn_per_e, locate, optics: Optics):
    """(the plane balanced by the settled gains, the gains, passes) from first_guess (module doc); locate(plane):
    psf_fit.first_lattice's answer for it (None: no lattice; the camera's response is then kept)."""
    gains = SiteGains(tuple(first_guess(frames)), (0.0, 0.0, 0.0), (), (0, 0, 0))
    for passes in range(1, MAX_PASSES + 1):
        plane = merge_psf(frames, wavelength_nm, camera, dn_per_e, gains)
        where = locate(plane)
        if where is None:
            return merge_psf(frames, wavelength_nm, camera, dn_per_e), None, passes
        new = site_gains(plane, colours, where, optics)
        step = np.abs(np.subtract(new.gains, gains.gains))
        gains = new
        if np.all(step <= np.maximum(0.5 * np.array(new.sigma), 1e-3)):
            break
    return merge_psf(frames, wavelength_nm, camera, dn_per_e, gains), gains, passes
