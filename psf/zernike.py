"""Zernike wavefront aberrations of the lens (psf.lens.Lens.zernike_waves): the terms, their check, W(ρ, θ).

OSA/ANSI normalised Zernike polynomials (Thibos, Applegate, Schwiegerling & Webb, "Standards for
reporting the optical aberrations of eyes", J. Refract. Surg. 18, S652, 2002; Noll, JOSA 66, 207, 1976):

    Z_n^m(ρ, θ) = N_n^m R_n^|m|(ρ) · cos(m θ)  (m ≥ 0),   N_n^m R_n^|m|(ρ) · sin(|m| θ)  (m < 0)
    N_n^m = √(2 (n + 1) / (1 + δ_m0))
    R_n^k(ρ) = Σ_{s=0}^{(n−k)/2} (−1)^s (n − s)! / (s! ((n + k)/2 − s)! ((n − k)/2 − s)!) ρ^(n − 2s)

on the unit disc ρ = r / (D/2) ≤ 1, θ from the +x axis towards +y. They are orthonormal over the disc,
(1/π) ∫ Z_j Z_k dA = δ_jk, and every term with n ≥ 1 has zero mean, so a term of coefficient a has RMS
a and a sum of terms RMS √(Σ a²). Examples: Z(2, 0) defocus, Z(2, ±2) astigmatism, Z(3, ±1) coma,
Z(4, 0) primary spherical aberration (balanced with defocus), Z(6, 0) secondary spherical.

The coefficients are in waves RMS at REFERENCE_NM; the wavefront error is an optical path difference,
W = (REFERENCE_NM / 1000) Σ a Z (µm), the same at every wavelength (no chromatic aberration): the pupil
phase at λ is 2π W / λ (a waves at 550 nm are a · 550 / λ waves at λ). Maréchal: the Strehl ratio is
≈ exp(−(2π σ)²) for an RMS of σ waves (Born & Wolf, Principles of Optics, §9.3).
"""
from __future__ import annotations

import math

import numpy as np

__all__ = ["ALLOWED", "MAX_ORDER", "MAX_RMS_WAVES", "REFERENCE_NM", "canonical", "max_slope", "radial", "rms_waves",
           "wavefront", "zernike"]

REFERENCE_NM = 550.0  # the wavelength of the coefficients' waves (the photopic peak; MTF charts' e-line: 546 nm)
MAX_ORDER = 10  # radial orders n ≤ 10: up to tertiary spherical Z(8, 0) and beyond
MAX_RMS_WAVES = 1.0  # total RMS: Strehl exp(−(2π)²) ≈ 7e-18 — no diffraction left, geometrical optics beyond


ALLOWED = (f"a list of [n, m, waves RMS at {REFERENCE_NM:g} nm] with 2 ≤ n ≤ {MAX_ORDER}, |m| ≤ n, n − |m| even, "
           f"each (n, m) once (n < 2, piston and tilt, only shift the image), total RMS ≤ {MAX_RMS_WAVES:g} wave")


def _fail(terms):
    raise ValueError(f"lens: zernike_waves = {terms!r}: expected {ALLOWED}")


def canonical(terms) -> tuple[tuple[int, int, float], ...]:
    """The terms as a sorted tuple of (n, m, waves), zero coefficients dropped; a ValueError of one line
    naming what is wrong otherwise (n from 2 to MAX_ORDER, |m| ≤ n, n − |m| even, each (n, m) once, a
    total RMS ≤ MAX_RMS_WAVES)."""
    if isinstance(terms, (str, bytes, dict)) or not hasattr(terms, "__iter__"):
        _fail(terms)
    out = {}
    for t in terms:
        if isinstance(t, (str, bytes)) or not hasattr(t, "__len__") or len(t) != 3:
            _fail(terms)
        n, m, a = t
        whole = all(isinstance(v, (int, np.integer)) and not isinstance(v, bool) for v in (n, m))
        number = isinstance(a, (int, float, np.floating, np.integer)) and not isinstance(a, bool) and math.isfinite(a)
        if not (whole and number and 2 <= n <= MAX_ORDER and abs(m) <= n and (n - abs(m)) % 2 == 0
                and (int(n), int(m)) not in out):
            _fail(terms)
        out[(int(n), int(m))] = float(a)
    if math.sqrt(sum(a * a for a in out.values())) > MAX_RMS_WAVES:
        _fail(terms)
    return tuple((n, m, a) for (n, m), a in sorted(out.items()) if a != 0.0)


def rms_waves(terms) -> float:
    """The wavefront's RMS over the pupil in waves at REFERENCE_NM: √(Σ a²) (orthonormal terms)."""
    return math.sqrt(sum(a * a for _, _, a in terms))


def radial(n: int, k: int, rho: np.ndarray) -> np.ndarray:
    """R_n^k(ρ) (module doc), k = |m|."""
    out = np.zeros_like(rho, dtype=np.float64)
    for s in range((n - k) // 2 + 1):
        c = (-1) ** s * math.factorial(n - s) / (
            math.factorial(s) * math.factorial((n + k) // 2 - s) * math.factorial((n - k) // 2 - s))
        out += c * rho ** (n - 2 * s)
    return out


def zernike(n: int, m: int, rho: np.ndarray, theta: np.ndarray) -> np.ndarray:
    """Z_n^m(ρ, θ), OSA/ANSI normalised (module doc)."""
    norm = math.sqrt(2 * (n + 1) / (1 + (m == 0)))
    angular = np.cos(m * theta) if m >= 0 else np.sin(-m * theta)
    return norm * radial(n, abs(m), rho) * angular


def wavefront(terms, rho: np.ndarray, theta: np.ndarray) -> np.ndarray:
    """Σ a Z_n^m(ρ, θ) in waves at REFERENCE_NM (0 for no terms)."""
    out = np.zeros(np.broadcast(rho, theta).shape)
    for n, m, a in terms:
        out += a * zernike(n, m, rho, theta)
    return out


def max_slope(terms, samples: int = 513) -> float:
    """max |∇W| over the unit disc, in waves per unit ρ (finite differences on a samples² grid): the finest
    pupil sampling the phase needs is δ ≤ λ / (2 · slope in length per length) (psf.plan.auto_pupil_samples)."""
    if not terms:
        return 0.0
    u = np.linspace(-1.0, 1.0, samples)
    x, y = np.meshgrid(u, u)
    rho, theta = np.hypot(x, y), np.arctan2(y, x)
    w = wavefront(terms, rho, theta)
    gy, gx = np.gradient(w, u, u)
    inside = rho <= 1.0
    return float(np.hypot(gx, gy)[inside].max())
