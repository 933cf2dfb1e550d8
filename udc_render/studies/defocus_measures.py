"""The defocus study's rig (udc_render.studies.defocus: its module doc has the formulas), its thin-lens
geometry, the blur measures of one kernel (edge spread, equivalent disc, MTFs, the diffraction limit)
and the depth of field read off them.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.optimize import brentq

from psf import Lens, layouts

FOCAL_LENGTH_UM = 6000.0
APERTURE_UM = 3333.0  # f/1.8
PIXEL_UM = 1.55
FOCUS_MM = 500.0
DISPLAYS = ("glass", "toled", "poled")  # at d = 0
D_GAP_MM = 2.0  # the full run's extra case: the T-OLED at d = D_GAP_MM (field-averaged kernels)
DISPLAY_SPECS = {"glass": (lambda: None, 0.0), "toled": (layouts.toled, 0.0), "poled": (layouts.poled, 0.0),
                 "toled_gap": (layouts.toled, D_GAP_MM)}  # name → (layout factory, display-to-lens gap d in mm)
F_REF_CPP = 0.25  # reference frequency (cycles/pixel)
F_BAND_CPP = 0.05  # the reference MTF is the mean over F_REF_CPP ± F_BAND_CPP, all orientations
RADIAL_STEP_CPP = 0.01  # annulus width of the orientation-averaged MTF curve
REL_LEVEL = 0.5
ABS_MTF = 0.1  # absolute DoF: the reference MTF ≥ this, whatever the display
COC_GEOM_PX = 2.0
GEOM_MIN_PX = 20.0
GEOM_TOL = 0.10
DIFF_TOL = 0.01
ESF_LO, ESF_HI = 0.1, 0.9
FREQS_CPP = np.linspace(0.0, 0.5, 101)
COLUMNS = ["display", "wavelength_nm", "object_distance_mm", "vergence_per_m", "defocus_per_m", "coc_geom_px",
           "esf_width_x_px", "esf_width_y_px", "esf_width_px", "disc_equiv_px", "disc_width_geom_px",
           "mtf_ref_x", "mtf_ref_y", "mtf_ref", "mtf50_cpp", "energy_outside", "transmittance", "peak"]


@dataclass(frozen=True)
class Config:
    """The sweep: wavelengths, kernel size and pupil sampling (None: the engine's auto), vergences
    1/z (m⁻¹; 0 = infinity; must hold 1/z_f), the vergences shown in the PSF and MTF panels, and the
    displays (DISPLAY_SPECS keys; the first three always DISPLAYS)."""
    quick: bool
    wavelengths_nm: tuple
    size_px: int
    pupil_samples: int | None
    vergences_per_m: tuple
    panel_vergences_per_m: tuple
    displays: tuple = DISPLAYS


FULL = Config(False, (450.0, 520.0, 640.0), 511, None,
              (0.0, 0.5, 1.0, 1.4, 1.6, 1.7, 1.75, 1.8, 1.85, 1.9, 1.95, 2.0, 2.05, 2.1, 2.15, 2.2, 2.25, 2.3, 2.4,
               2.6, 3.0, 4.0, 5.0, 6.5, 8.0, 10.0),
              (0.0, 1.0, 1.8, 2.0, 2.2, 3.0, 5.0, 10.0), DISPLAYS + ("toled_gap",))
QUICK = Config(True, (520.0,), 127, 256, (0.0, 1.0, 1.7, 1.85, 2.0, 2.15, 2.3, 3.0, 5.0, 10.0),
               (0.0, 1.85, 2.0, 3.0, 10.0))


# ----------------------------------------------------------------------------------------------
# Thin-lens geometry


def focus_vergence_per_m(focus_mm: float = FOCUS_MM) -> float:
    """v_f = 1000 / z_f (m⁻¹)."""
    return 1000.0 / focus_mm


def object_distance_mm(vergence_per_m: float) -> float:
    """z = 1000 / v (mm); infinity at v = 0."""
    return math.inf if vergence_per_m == 0 else 1000.0 / vergence_per_m


def lens_at(vergence_per_m: float, focus_mm: float = FOCUS_MM) -> Lens:
    """The study's lens focused at focus_mm, imaging an object at vergence v."""
    return Lens(FOCAL_LENGTH_UM, APERTURE_UM, focus_mm, object_distance_mm(vergence_per_m))


def geometric_coc_px(lens: Lens, pixel_um: float = PIXEL_UM) -> float:
    """b = D · z_i · |1/z_f − 1/z| in pixels (thin lens, sensor at the focus plane's image)."""
    return lens.aperture_um * lens.image_distance_um * abs(lens.defocus_curvature_per_um) / pixel_um


def geometric_dof_vergence_per_m(lens: Lens, coc_px: float = COC_GEOM_PX, pixel_um: float = PIXEL_UM) -> tuple:
    """(far, near) vergences (m⁻¹) where b = coc_px: v_f ∓ coc · p / (D z_i) · 10⁶ (far clipped at 0)."""
    half = coc_px * pixel_um / (lens.aperture_um * lens.image_distance_um) * 1e6
    v_f = 1e6 / (lens.focus_distance_mm * 1000)
    return max(v_f - half, 0.0), v_f + half


# ----------------------------------------------------------------------------------------------
# Edge spread


def lsf(kernel: np.ndarray, axis: str) -> np.ndarray:
    """The line-spread function along x (Σ over rows) or y (Σ over columns) of a [S, S] kernel."""
    return np.asarray(kernel, dtype=np.float64).sum(axis=0 if axis == "x" else 1)


def esf_width_px(line: np.ndarray, lo: float = ESF_LO, hi: float = ESF_HI) -> float:
    """The lo–hi rise width (px) of the ESF = running sum of the LSF (its values at the pixel edges,
    normalised to end at 1), crossings by linear interpolation between edges."""
    esf = np.concatenate([[0.0], np.cumsum(line)])
    esf /= esf[-1]
    edges = np.arange(esf.size) - 0.5

    def crossing(level):
        i = int(np.argmax(esf >= level))  # first edge at or above level (the ESF is monotone for k ≥ 0)
        if i == 0:
            return edges[0]
        return edges[i - 1] + (level - esf[i - 1]) / (esf[i] - esf[i - 1])
    return float(crossing(hi) - crossing(lo))


def disc_esf(x_px: np.ndarray, diameter_px: float) -> np.ndarray:
    """ESF of a uniform disc of diameter b: F = 1/2 + (t√(1−t²) + asin t)/π, t = clip(2x/b, −1, 1)."""
    if diameter_px <= 0:
        return (np.asarray(x_px) >= 0).astype(np.float64)
    t = np.clip(2 * np.asarray(x_px, dtype=np.float64) / diameter_px, -1.0, 1.0)
    return 0.5 + (t * np.sqrt(1 - t * t) + np.arcsin(t)) / math.pi


def disc_lsf_px(diameter_px: float, size_px: int) -> np.ndarray:
    """The pixel-integrated LSF of the disc on size_px pixels centred at size_px // 2: F(j + ½) − F(j − ½)."""
    j = np.arange(size_px) - size_px // 2
    return disc_esf(j + 0.5, diameter_px) - disc_esf(j - 0.5, diameter_px)


def disc_esf_width_px(diameter_px: float) -> float:
    """esf_width_px of the disc (diameter b) convolved with the pixel: the geometric reference."""
    return esf_width_px(disc_lsf_px(diameter_px, 2 * int(math.ceil(diameter_px)) + 9))


def equivalent_disc_px(width_px: float) -> float:
    """The disc diameter b' with disc_esf_width_px(b') = width_px (0 below a point's width, 0.8 px)."""
    floor = disc_esf_width_px(0.0)
    if width_px <= floor:
        return 0.0
    hi = 2.0 * width_px + 4.0  # w ≈ 0.69 b for large b: this brackets the root
    return float(brentq(lambda b: disc_esf_width_px(b) - width_px, 0.0, hi, xtol=1e-4))


# ----------------------------------------------------------------------------------------------
# MTF


def mtf_of_line(line: np.ndarray, freqs_cpp=FREQS_CPP) -> np.ndarray:
    """|Σ_j LSF[j] e^(−2πi f (j − S//2))| / Σ LSF at the frequencies f (cycles/px): the MTF along an axis."""
    j = np.arange(line.size) - line.size // 2
    otf = np.exp(-2j * math.pi * np.outer(freqs_cpp, j)) @ line
    return np.abs(otf) / line.sum()


def mtf_2d(kernel: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(|f| in cycles/px, |DFT| / DFT(0)) on the kernel's S² frequency grid (centre at S // 2 as origin)."""
    k = np.asarray(kernel, dtype=np.float64)
    otf = np.abs(np.fft.fft2(np.fft.ifftshift(k)))
    f = np.fft.fftfreq(k.shape[-1])
    return np.hypot(f[None, :], f[:, None]), otf / otf[0, 0]


def band_mtf(kernel: np.ndarray, lo_cpp: float, hi_cpp: float) -> float:
    """Mean of the 2-D MTF over the annulus lo ≤ |f| < hi (all orientations)."""
    r, m = mtf_2d(kernel)
    sel = (r >= lo_cpp) & (r < hi_cpp)
    return float(m[sel].mean())


def radial_mtf(kernel: np.ndarray, step_cpp: float = RADIAL_STEP_CPP) -> tuple[np.ndarray, np.ndarray]:
    """(annulus centres, orientation-averaged MTF): the 2-D MTF's mean over annuli of width step, 0…0.5,
    with MTF(0) = 1 first. A display's MTF is a comb of period p · pixel / (λ z_i) cycles/px (the
    orders' spacing), so point values along an axis depend on where f falls between its teeth."""
    r, m = mtf_2d(kernel)
    edges = np.arange(0.0, 0.5 + step_cpp / 2, step_cpp)
    idx = np.digitize(r.ravel(), edges) - 1
    ok = (idx >= 0) & (idx < edges.size - 1)
    sums = np.bincount(idx[ok], weights=m.ravel()[ok], minlength=edges.size - 1)
    counts = np.bincount(idx[ok], minlength=edges.size - 1)
    keep = counts > 0
    centres = (edges[:-1] + edges[1:]) / 2
    return np.concatenate([[0.0], centres[keep]]), np.concatenate([[1.0], sums[keep] / counts[keep]])


def mtf50_cpp(freqs_cpp: np.ndarray, mtf: np.ndarray) -> float:
    """The lowest frequency where the MTF falls to 0.5 (linear interpolation); nan if it never does."""
    below = np.nonzero(mtf < 0.5)[0]
    if below.size == 0 or below[0] == 0:
        return math.nan
    i = below[0]
    return float(freqs_cpp[i - 1] + (mtf[i - 1] - 0.5) / (mtf[i - 1] - mtf[i]) * (freqs_cpp[i] - freqs_cpp[i - 1]))


def circular_mtf(nu: np.ndarray) -> np.ndarray:
    """Diffraction-limited MTF of a circular pupil, (2/π)(acos ν − ν√(1 − ν²)), ν = f λ N (0 past ν = 1)."""
    n = np.clip(np.abs(np.asarray(nu, dtype=np.float64)), 0.0, 1.0)
    return 2 / math.pi * (np.arccos(n) - n * np.sqrt(1 - n * n))


def diffraction_limit(freqs_cpp, wavelength_nm: float, f_number: float, pixel_um: float = PIXEL_UM,
                      folded: bool = True) -> np.ndarray:
    """The sampled kernel's diffraction-limited OTF: Σ_k M(|f + k| λ N / p) sinc(f + k), k over the orders
    below the cutoff (k = 0 only when not folded); the pixel's sinc is sin(πf)/(πf)."""
    f = np.asarray(freqs_cpp, dtype=np.float64)
    cutoff_cpp = pixel_um / (wavelength_nm * 1e-3 * f_number)
    orders = range(-int(cutoff_cpp) - 1, int(cutoff_cpp) + 2) if folded else (0,)
    return sum(circular_mtf((f + k) * wavelength_nm * 1e-3 * f_number / pixel_um) * np.sinc(f + k) for k in orders)


# ----------------------------------------------------------------------------------------------
# Depth of field


def dof_interval(vergences_per_m, values, focus_per_m: float, threshold: float) -> tuple[float, float]:
    """(far, near) vergences bounding the run of values ≥ threshold that holds the focus, each crossing
    interpolated linearly in v; a side that never falls below ends at the grid's end. (nan, nan) if
    the focus itself is below."""
    v = np.asarray(vergences_per_m, dtype=np.float64)
    m = np.asarray(values, dtype=np.float64)
    order = np.argsort(v)
    v, m = v[order], m[order]
    i0 = int(np.argmin(np.abs(v - focus_per_m)))
    if m[i0] < threshold:
        return math.nan, math.nan

    def walk(step):
        i = i0
        while 0 <= i + step < v.size and m[i + step] >= threshold:
            i += step
        if not 0 <= i + step < v.size:
            return float(v[i])
        j = i + step
        return float(v[i] + (m[i] - threshold) / (m[i] - m[j]) * (v[j] - v[i]))
    return walk(-1), walk(+1)


def _distance_mm(vergence_per_m: float) -> float:
    """object_distance_mm of a vergence; NaN (no crossing) stays NaN."""
    return object_distance_mm(vergence_per_m) if not math.isnan(vergence_per_m) else math.nan


def dof_rows(rows: list[dict], cfg: Config) -> list[dict]:
    """One row per display and wavelength: in-focus reference MTF, the relative and absolute DoF
    (distances and vergence widths), and the geometric DoF."""
    v_f = focus_vergence_per_m()
    far_g, near_g = geometric_dof_vergence_per_m(lens_at(v_f))
    out = []
    for wl in cfg.wavelengths_nm:
        for disp in cfg.displays:
            sel = [r for r in rows if r["display"] == disp and r["wavelength_nm"] == wl]
            vs, ms = [r["vergence_per_m"] for r in sel], [r["mtf_ref"] for r in sel]
            m0 = row_at(rows, disp, wl, v_f)["mtf_ref"]
            row = {"display": disp, "wavelength_nm": wl, "mtf_ref_focus": m0, "geom_far_mm": object_distance_mm(far_g),
                   "geom_near_mm": object_distance_mm(near_g), "geom_width_per_m": near_g - far_g}
            for name, thr in (("rel", REL_LEVEL * m0), ("abs", ABS_MTF)):
                far, near = dof_interval(vs, ms, v_f, thr)
                row.update({f"{name}_threshold": thr, f"{name}_far_mm": _distance_mm(far),
                            f"{name}_near_mm": _distance_mm(near),
                            f"{name}_width_per_m": near - far})
            out.append(row)
    return out


def row_at(rows: list[dict], display: str, wavelength_nm: float, vergence_per_m: float) -> dict:
    return next(r for r in rows if r["display"] == display and r["wavelength_nm"] == wavelength_nm
                and abs(r["vergence_per_m"] - vergence_per_m) < 1e-9)


def blur_measures(kernel: np.ndarray) -> dict:
    """Edge-spread widths (x, y, mean) and the equivalent disc diameter; MTF at F_REF_CPP along x and y;
    the reference MTF (the 2-D MTF's mean over F_REF_CPP ± F_BAND_CPP, all orientations); MTF50 of the
    orientation-averaged MTF; the peak (energy in the brightest pixel)."""
    lx, ly = lsf(kernel, "x"), lsf(kernel, "y")
    wx, wy = esf_width_px(lx), esf_width_px(ly)

    def at(line):
        return float(mtf_of_line(line, [F_REF_CPP])[0])
    return {"esf_width_x_px": wx, "esf_width_y_px": wy, "esf_width_px": (wx + wy) / 2,
            "disc_equiv_px": equivalent_disc_px((wx + wy) / 2), "mtf_ref_x": at(lx), "mtf_ref_y": at(ly),
            "mtf_ref": band_mtf(kernel, F_REF_CPP - F_BAND_CPP, F_REF_CPP + F_BAND_CPP),
            "mtf50_cpp": mtf50_cpp(*radial_mtf(kernel)), "peak": float(np.max(kernel))}
