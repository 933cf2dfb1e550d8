"""γ per RGGB channel from the paper's white-square pair, and the display's transmission T(λ) fitted to it
(--white GLASS DISPLAY).

The paper calibrates γ with a white square on the monitor, captured through a glass panel and through
the display (l.210): γ_c = (display level) / (glass level) per channel, the display capture at its own
gain. Here: the square is the largest connected component (scipy.ndimage.label) of the glass capture's level
above half its 99.5th percentile, the level a 3 × 3 median of the channels' mean (of each 2 × 2 CFA cell), so
that a hot pixel, a reflection or a ghost elsewhere in the frame is another component, or none; the component
must fill at least MIN_FILL of its bounding box (a square, not a blob); its central half (each side) is the
region; per channel (a CFA's sites named by the pattern, Gr the green on the red rows; a colour image's R, G,
G, B; a grey image's one value four times) γ_c = mean(display) / mean(glass) above
black, σ_γ = std(display − γ glass) / (√n mean(glass)).
T(λ) (optics.gamma): γ_c = G Σ_k W_ck T_k g_k / Σ_k W_ck g⁰_k, W the camera's electrons per band from the
monitor's white, G the display capture's gain over the glass capture's (--white-gain), and g the share of the
aperture's power that the measured square brings to the region, for the fitted layout and (g⁰) the bare lens:
g_k = τ_k (1 − o_k) + τ_k a_k (calibration.fit_gains.square_gains), the kernels' share inside the KERNEL_PX
window (psf.compute_kernels at the band centres) and a_k the far field's from the square found here
(optics.far_field.far_square_share, its sides and the region's in sensor pixels; the far field computed over
the capture's frame). What the far field adds
depends on the square: on the P-OLED preset nothing for a square inside the window, 1.6 % in R for the default
rig's 576-px square around a 60-px region, 4–5 % for a 1200-px square or a white frame (docs/PHYSICS.md §8); a
fit without it put T that much too high. Flat T: weighted least squares over R, G, B; when the channels
disagree with it (χ²/dof > 4 and a channel more than 2 % off), the polyimide T(λ) of the P-OLED preset
(scale, absorption edge, cathode) is fitted instead (optics.displays.fit_poled_transmission), σ by its
Jacobian.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from psf import Lens
from udc_render.calibration.fit_gains import square_gains
from udc_render.fit.inputs import FitError, Frame, saturated
from udc_render.optics.displays import Display, Transmission, fit_poled_transmission, poled_transmission
from udc_render.optics.gamma import channel_gamma, white_weights

CHANNEL_NAMES = ("R", "Gr", "Gb", "B")
MIN_FILL = 0.9  # the square's component fills at least this share of its bounding box
KERNEL_PX = 511
SENSOR_UM = (2048 * 1.55, 1024 * 1.55)  # the paper's frame: band_gains' default when no capture gives one


def channels(frame: Frame) -> list[np.ndarray]:
    """[4] (R, Gr, Gb, B) masks [H, W] of a frame's pixels (module doc)."""
    h, w = frame.shape
    if frame.kind != "cfa":
        full = np.ones((h, w), bool)
        return [full] * 4
    out = [np.zeros((h, w), bool) for _ in range(4)]
    rows, cols = np.mgrid[0:h, 0:w]
    for i in (0, 1):
        for j in (0, 1):
            c = int(frame.sites[i, j])
            name = {0: 0, 2: 3}.get(c, 1 if frame.sites[i, 1 - j] == 0 else 2)
            out[name] |= (rows % 2 == i) & (cols % 2 == j)
    return out


def _planes(frame: Frame) -> list[np.ndarray]:
    """The frame's value above black per channel (R, Gr, Gb, B) and the saturated pixels."""
    above = frame.above_black()
    if frame.kind == "rgb":
        return [above[..., c] for c in (0, 1, 1, 2)]
    return [above] * 4


@dataclass(frozen=True)
class WhiteSquare:
    """γ (R, Gr, Gb, B) ± σ measured on a white-square pair, the pixels per channel, and where: the square's and
    the region's sides and the frame's (x, y) in sensor pixels."""
    gamma: np.ndarray
    sigma: np.ndarray
    pixels: int
    square_xy_px: tuple[int, int]
    region_xy_px: tuple[int, int]
    frame_xy_px: tuple[int, int]


@dataclass(frozen=True)
class WhiteFit:
    """What the white-square pair measured (WhiteSquare: γ ± σ, pixels, sides), the fitted transmission, its
    parameters ± σ, the γ (R, Gr, Gb, B) it gives, and the gain."""
    measured: WhiteSquare
    transmission: Transmission
    params: dict
    gamma_model: np.ndarray
    gain: float


def find_square(frame: Frame, level: np.ndarray) -> tuple[int, int, int, int]:
    """(first row, last row, first column, last column) of the white square (module doc) in `level` [H, W]."""
    from scipy import ndimage
    if frame.kind == "cfa":
        level = ndimage.uniform_filter(level, 2, mode="nearest")
    level = ndimage.median_filter(level, 3, mode="nearest")
    labels, n = ndimage.label(level > 0.5 * np.percentile(level, 99.5))
    sizes = np.bincount(labels.ravel())[1:]
    if n == 0 or sizes.max() < 64:
        raise FitError(f"--white {frame.path}: no white square found (no 64 connected pixels above half the "
                       "brightest): expected a white square on black")
    k = int(np.argmax(sizes))
    rows, cols = ndimage.find_objects(labels)[k]
    fill = sizes[k] / ((rows.stop - rows.start) * (cols.stop - cols.start))
    if fill < MIN_FILL:
        raise FitError(f"--white {frame.path}: the largest bright region fills {fill:.0%} of its bounding box: "
                       f"expected a white square (≥ {MIN_FILL:.0%}) on black")
    return rows.start, rows.stop - 1, cols.start, cols.stop - 1


def measure_gamma(glass: Frame, display: Frame) -> WhiteSquare:
    """γ and σ per channel, and the square and region they come from (module doc)."""
    if glass.shape != display.shape:
        raise FitError(f"--white: {glass.path} and {display.path} differ in size: expected one camera and framing")
    gp, dp = _planes(glass), _planes(display)
    r0, r1, c0, c1 = find_square(glass, np.mean(gp, axis=0))
    region = np.zeros(glass.shape, bool)
    rows_r = slice(r0 + (r1 - r0) // 4, r1 - (r1 - r0) // 4 + 1)
    cols_r = slice(c0 + (c1 - c0) // 4, c1 - (c1 - c0) // 4 + 1)
    region[rows_r, cols_r] = True
    gamma, sigma, n = np.zeros(4), np.zeros(4), []

    def raw(f, c):
        return f.dn[..., (0, 1, 1, 2)[c]] if f.kind == "rgb" else f.dn
    for c, mask in enumerate(channels(glass)):
        sel = region & mask
        for f in (glass, display):
            if saturated(f, raw(f, c))[sel].any():
                raise FitError(f"--white {f.path}: the white square is saturated in channel {CHANNEL_NAMES[c]}: "
                               "expected captures below the white level (a shorter exposure)")
        g, d = gp[c][sel], dp[c][sel]
        gamma[c] = d.mean() / g.mean()
        sigma[c] = np.std(d - gamma[c] * g) / (math.sqrt(g.size) * g.mean())
        n.append(g.size)
    return WhiteSquare(gamma, sigma, min(n), (int(c1 - c0 + 1), int(r1 - r0 + 1)),
                       (cols_r.stop - cols_r.start, rows_r.stop - rows_r.start), (glass.shape[1], glass.shape[0]))


def band_gains(layout, lens: Lens, edges_nm, pixel_um: float, square_xy_px: tuple | None = None,
               region_xy_px: tuple = (1, 1), frame_um: tuple = SENSOR_UM) -> tuple[np.ndarray, np.ndarray]:
    """(display, glass) g_k at the band centres for a white square of square_xy_px around a region of
    region_xy_px, sensor px, on a frame_um sensor (module doc; square None: τ_k (1 − o_k), the core alone); the
    bare lens's through the kernel cache (the same every run), the fitted layout's not."""
    centres = 0.5 * (edges_nm[1:] + edges_nm[:-1])
    return tuple(square_gains(lay, lens, centres, pixel_um, KERNEL_PX, tuple(frame_um), square_xy_px, region_xy_px,
                              use_cache=lay is None) for lay in (layout, None))


def _rgb(gamma_rggb: np.ndarray) -> np.ndarray:
    return np.array([gamma_rggb[0], 0.5 * (gamma_rggb[1] + gamma_rggb[2]), gamma_rggb[3]])


def fit_transmission(square: WhiteSquare, layout, lens: Lens, edges_nm, pixel_um: float, camera: str, gain: float):
    """(Transmission, {parameter: (value, σ)}, γ (R, Gr, Gb, B) it gives) of the module doc."""
    gamma, sigma = square.gamma, square.sigma
    frame_um = (square.frame_xy_px[0] * pixel_um, square.frame_xy_px[1] * pixel_um)  # the far field's extent
    d_gain, g_gain = band_gains(layout, lens, edges_nm, pixel_um, square.square_xy_px, square.region_xy_px, frame_um)
    w = white_weights(edges_nm, camera)
    unit = channel_gamma(w, Display("t", layout, Transmission("flat", 1.0), gain), d_gain, g_gain, edges_nm)
    a = np.array([unit[0], unit[1], unit[1], unit[2]])
    inv = 1.0 / sigma ** 2
    t = float(np.sum(inv * gamma * a) / np.sum(inv * a * a))
    chi2 = float(np.sum(inv * (gamma - t * a) ** 2)) / 3
    st = math.sqrt(max(1.0, chi2) / np.sum(inv * a * a))
    if chi2 <= 4 or np.max(np.abs(gamma / (t * a) - 1)) <= 0.02:
        if not 0 < t <= 1:
            raise FitError(f"--white: the flat transmission fitted to γ is {t:.3g}: expected 0 < T ≤ 1 (is "
                           "--white-gain the display capture's gain over the glass capture's?)")
        return Transmission("flat", t), {"value": (t, st)}, t * a
    p = fit_poled_transmission(d_gain, g_gain, edges_nm, camera, target=tuple(_rgb(gamma)), gain=gain, layout=layout)

    def model(q):
        return channel_gamma(w, Display("t", layout, poled_transmission(*q), gain), d_gain, g_gain, edges_nm)
    jac = np.stack([(model(np.add(p, np.eye(3)[i] * h)) - model(np.subtract(p, np.eye(3)[i] * h))) / (2 * h)
                    for i, h in enumerate((1e-4, 0.05, 0.05))], axis=1)
    s_rgb = np.array([sigma[0], 0.5 * math.hypot(sigma[1], sigma[2]), sigma[3]])
    cov = np.linalg.pinv(jac) @ np.diag(s_rgb ** 2) @ np.linalg.pinv(jac).T
    g = model(p)
    names = ("scale", "edge_nm", "cathode_nm")
    params = {n: (float(v), float(math.sqrt(cov[i, i]))) for i, (n, v) in enumerate(zip(names, p))}
    return poled_transmission(*p), params, np.array([g[0], g[1], g[1], g[2]])


def fit_white(glass: Frame, display: Frame, layout, lens: Lens, edges_nm, pixel_um: float, camera: str,
              gain: float) -> WhiteFit:
    """γ and T(λ) of the module doc."""
    square = measure_gamma(glass, display)
    trans, params, model = fit_transmission(square, layout, lens, np.asarray(edges_nm, float), pixel_um, camera, gain)
    return WhiteFit(square, trans, params, model, gain)
