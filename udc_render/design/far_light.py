"""Where a cell's light goes on the sensor: its shares inside the kernel's square window and inside the lens's
acceptance disc (udc_render.optics.far_field.acceptance_um), in closed form from the cell's Fourier transform.

A display of cells of period P (any D4 tiling) in front of the lens sends the share of its transmitted power

    s(R) = ∫_R |Ĉ(ν)|² dν / ∫ |C(x)|² dx,        Ĉ(ν) = Σ_jk a_jk δ² sinc(ν_y δ) sinc(ν_x δ) e^{−2πi ν·x_jk}

to the sensor region R = λ z ν (z: the image distance), C the cell's c × c squares of δ µm. The aperture's blur
(λz/D ≈ 1 µm) and the pixels are left out, and the turned tiling's power spectrum is the cell's |Ĉ|² averaged
over its D4 turns, which leave a square window and a disc unchanged. Parseval's sum is taken on a grid of step
1 / (pad P) up to the region's largest frequency (one 8 µm square's window share: 1.9e-5 / 3.4e-5 / 1.4e-5 off Si's
closed form at pad 4 / 8 / 16, the Riemann sum's edge; 2 s for the 2520² T-OLED cell): a check of the engine's
energy_outside that shares no code with it (psf.engine: the tiled pupil's FFT and exact pixel integration), and the
light past the window that the simulator's far field keeps (within the acceptance) or loses (beyond it).

The light it keeps lands as a veil of about the scene's mean μ: a restorer whose kernel holds only the window
(plain DeP) leaves it in its estimate, at its DC gain of 1, relative to the window's light. veil_cost_db is the PSNR
that costs against the same restorer given the far field (docs/guides/design.md, the arranged tiling: within
0.02 dB of `study layout-trained`'s plain DeP for the arranged designs and the turned T-OLED).
"""
from __future__ import annotations

import numpy as np

__all__ = ["light_shares", "veil_cost_db"]


def light_shares(cell: np.ndarray, pixel_um: float, wavelength_um: float, image_distance_um: float,
                 half_window_um: float, acceptance_um: float, pad: int = 4) -> dict:
    """{window, acceptance}: the shares of the cell's transmitted power (amplitudes [c, c] of pixel_um squares)
    inside the square |u|, |v| ≤ half_window_um and the disc |u| ≤ acceptance_um on the sensor (module doc)."""
    a = np.asarray(cell, np.float64)
    c = a.shape[0]
    scale = wavelength_um * image_distance_um  # µm on the sensor per cycle / µm at the display
    reach = max(half_window_um * np.sqrt(2), acceptance_um) / scale
    step = 1.0 / (pad * c * pixel_um)
    nu = np.arange(-np.ceil(reach / step), np.ceil(reach / step) + 1) * step
    x = (np.arange(c) + 0.5) * pixel_um
    m = np.exp(-2j * np.pi * np.outer(nu, x)) * (pixel_um * np.sinc(nu * pixel_um))[:, None]
    power = np.abs(m @ a @ m.T) ** 2 * step ** 2 / ((a ** 2).sum() * pixel_um ** 2)
    u = nu * scale
    square = (np.abs(u)[:, None] <= half_window_um) & (np.abs(u)[None, :] <= half_window_um)
    disc = np.hypot(u[:, None], u[None, :]) <= acceptance_um
    return {"window": float(power[square].sum()), "acceptance": float(power[disc].sum())}


def veil_cost_db(window: np.ndarray, acceptance: np.ndarray, psnr_given_far_db: float, mean_level: float) -> float:
    """The PSNR (dB) lost to the veil of the kept far light: 10 log10(1 + mean_c ((a_c − w_c) / w_c)² μ² / m),
    w_c, a_c a channel's shares inside the window and the acceptance (light_shares), m = 10^(−PSNR / 10) the error
    of the restorer given the far field (PSNR of a unit peak), μ the scene's mean (module doc)."""
    w, a = np.asarray(window, np.float64), np.asarray(acceptance, np.float64)
    veil = float(np.mean(((a - w) / w) ** 2)) * mean_level ** 2
    return float(10 * np.log10(1 + veil / 10 ** (-psnr_given_far_db / 10)))
