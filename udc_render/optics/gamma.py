"""γ, the one definition (docs/PHYSICS.md §2): the level of a flat white field seen through a display,
relative to the same field through glass at gain 1, per camera channel. It is what the paper's
calibration measures (a white square with and without the display) and what the spectral synthesis
produces:

    γ_c = gain · Σ_k W_ck T_k τ_k (1 − o_k) / Σ_k W_ck τ⁰_k (1 − o⁰_k)

W_ck: electrons per band k in channel c from the white through the bare lens (white band radiance
× photon weights × Δλ); T_k: the display's band-mean transmission; τ_k, o_k: its kernels'
transmittance and energy outside the window at the band centres; τ⁰_k, o⁰_k: the bare lens's.
The per-channel synthesis of display files, calibration's truth and DeP's known γ all call
display_gamma; the transmission fits of the presets call channel_gamma.
"""
from __future__ import annotations

import numpy as np

from udc_render.content import spectra
from udc_render.sensor import photon_weights

DEFAULT_PANEL = ("Apple Studio Display", 300.0)  # the monitor scene's panel (scenes/monitor.toml)


def kernel_gain(kernel_set) -> np.ndarray:
    """[K] τ_k (1 − o_k): the share of the bare aperture's power inside a KernelSet's window."""
    return np.asarray(kernel_set.transmittance, float) * (1 - np.asarray(kernel_set.energy_outside, float))


def panel_white_bands(edges_nm, white_point: str = "D65") -> np.ndarray:
    """[K] band-mean radiance of the default monitor panel's full white (relative units)."""
    prim, _ = spectra.monitor_primaries(*DEFAULT_PANEL, None, white_point)
    return spectra.band_means(prim.sum(axis=0), edges_nm)


def white_weights(edges_nm, camera: str, white_bands=None) -> np.ndarray:
    """W [3, K]: electrons per band and camera channel of a white (relative units); white_bands [K]
    the white's band radiance (None: the default panel's D65 white)."""
    white = panel_white_bands(edges_nm) if white_bands is None else np.asarray(white_bands, float)
    return photon_weights(edges_nm, camera) * white[None, :] * np.diff(np.asarray(edges_nm, float))[None, :]


def channel_gamma(band_weights: np.ndarray, display, display_gain_k: np.ndarray, glass_gain_k: np.ndarray,
                  edges_nm) -> np.ndarray:
    """γ (R, G, B) by the formula of the module doc, from W [3, K] and the kernels' τ(1 − o) [K]."""
    t = display.transmission.band_means(edges_nm)
    return display.gain * (band_weights @ (t * display_gain_k)) / (band_weights @ glass_gain_k)


def display_gamma(display, display_kernels, glass_kernels, edges_nm, camera: str, white_bands=None) -> np.ndarray:
    """γ (R, G, B) of `display` from its band kernels and the bare lens's (module doc)."""
    w = white_weights(edges_nm, camera, white_bands)
    return channel_gamma(w, display, kernel_gain(display_kernels), kernel_gain(glass_kernels), edges_nm)
