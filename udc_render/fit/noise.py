"""λ_read and λ_shot per RGGB channel from repeated frames (--noise-frames DIR): the paper's regression
(l.265), var = λ_read + λ_shot w, in normalised units w = (DN − black) / (white − black).

DIR holds the frames of one static scene (any pattern with dark and bright parts); each sub-folder one more
series (another exposure). Per pixel i of a series of N_i ≥ 2 frames: its mean w̄_i and its sample variance
s_i² = Σ (w − w̄_i)² / (N_i − 1), which has N_i − 1 degrees of freedom (the N residuals from their own mean
are not independent). A pixel is left out when any of its frames is at a clip (DN 0, or the saturation)
or its mean lies within CLIP_SIGMAS σ of one (its residuals would be cut: σ from the previous pass's line;
the first pass takes the pixels of FIRST_PASS),
and so is an outlier (a hot or flickering pixel, a cosmic ray): s_i² above the 1 − OUTLIER_P quantile of
its χ² law (for Gaussian noise ν_i s_i² / μ_i is χ² with ν_i = N_i − 1 degrees of freedom, μ_i = λ_read +
λ_shot w̄_i; s² is independent of w̄, so taking μ at the measured mean does not bias it). The pixels go into
NOISE_BINS quantile bins of w̄; per bin v_b = Σ ν_i s_i² / Σ ν_i, whose mean is the line at
w̄_b = Σ ν_i w̄_i / Σ ν_i, and whose variance is 2 Σ ν_i μ_i² / (Σ ν_i)² (each pixel's μ_i: a bin across a
steep part of the line holds a mixture of variances, whose scatter the bin's mean μ alone understates; the
darkest bin's pulls spread 1.23× with it). The line is the least squares weighted by those variances,
re-weighted from the line four times, its covariance (AᵀWA)⁻¹, widened by χ²/dof where the bins' χ² is
beyond its 1 − WIDEN_P quantile (noise that is not Gaussian, a scene that moved; a widening at every χ²/dof
above 1 would hide a σ stated too small, such as one that counted N degrees of freedom instead of N − 1).
The clips' exclusion takes σ from the line's upper 2 σ band.

A λ below 0: within NEGATIVE_SIGMAS σ of 0, the line is fitted again with that λ held at 0 (noted, and
written as 0 in both sensor.toml and fit.json); further below, refused (the frames do not follow the
model: a wrong black level or saturation, or a scene that changed).
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from udc_render.fit.inputs import SUFFIXES, FitError, Frame, read_frames
from udc_render.fit.white import CHANNEL_NAMES, channels

NOISE_BINS = 40
CLIP_SIGMAS = 4.0
OUTLIER_P = 1e-6
WIDEN_P = 0.01  # the covariance is widened by χ²/dof only where the bins' χ² exceeds its 99th percentile
FIRST_PASS = (0.05, 0.95)  # the first line's pixels (w̄), before the line gives each pixel's σ to the clips
NEGATIVE_SIGMAS = 4.0  # a λ further below 0 is refused; above, held at 0 (a λ near 0 is negative half the time)
MIN_PIXELS = 200  # per channel, after the clips


@dataclass(frozen=True)
class NoiseFit:
    """λ_read, λ_shot (R, Gr, Gb, B) ± σ, the frames and series used, the pixels per channel that entered the
    fit, the levels, the bit depth and what was held at 0."""
    lambda_read: np.ndarray
    lambda_read_sigma: np.ndarray
    lambda_shot: np.ndarray
    lambda_shot_sigma: np.ndarray
    frames: int
    series: int
    pixels: tuple
    black_dn: float
    white_dn: float
    bits: int
    notes: tuple = ()

    def dn_per_e(self) -> float:
        """κ = λ_shot (white − black): DN per electron (the mean of the channels)."""
        return float(np.mean(self.lambda_shot) * (self.white_dn - self.black_dn))


def series_files(folder: Path) -> list[list[Path]]:
    """The image files of the folder and of each sub-folder, one list each (sorted by name)."""
    folder = Path(folder)
    if not folder.is_dir():
        raise FitError(f"--noise-frames {folder}: no such folder: expected a folder of repeated frames")
    groups = [folder] + sorted(p for p in folder.iterdir() if p.is_dir())
    files = [sorted(p for p in g.iterdir() if p.is_file() and p.suffix.lower() in SUFFIXES) for g in groups]
    return [f for f in files if len(f) >= 2]


@dataclass(frozen=True)
class PixelStats:
    """Per pixel of one channel: mean w̄, sample variance s², its degrees of freedom, and its distance to the
    clips in w (below: w̄ − the black clip; above: 1 − w̄), and whether a frame touched a clip."""
    mean: np.ndarray
    var: np.ndarray
    dof: np.ndarray
    below: np.ndarray
    above: np.ndarray
    clipped: np.ndarray


def pixel_stats(frames: list[Frame], mask: np.ndarray) -> PixelStats:
    """The statistics of the masked pixels of one series (module doc)."""
    f0 = frames[0]
    span = f0.saturation_dn - f0.black_dn
    black = np.broadcast_to(f0.black(), f0.dn.shape)[mask]
    raw = np.stack([f.dn[mask] for f in frames])
    w = (raw - black) / span
    clipped = np.any((raw <= 0) | (raw >= f0.saturation_dn - 0.5), axis=0)
    mean = w.mean(axis=0)
    return PixelStats(mean, w.var(axis=0, ddof=1), np.full(mean.shape, len(frames) - 1.0), mean + black / span,
                      1.0 - mean, clipped)


def _join(stats: list[PixelStats]) -> PixelStats:
    return PixelStats(*(np.concatenate([getattr(s, k) for s in stats]) for k in PixelStats.__dataclass_fields__))


def line_fit(s: PixelStats, keep: np.ndarray, hold: int | None = None) -> tuple[np.ndarray, np.ndarray]:
    """(λ_read, λ_shot), their covariance: the weighted line through the kept pixels' bins (module doc); hold 0
    or 1: that λ held at 0."""
    from scipy.stats import chi2
    idx = np.nonzero(keep)[0]
    idx = idx[np.argsort(s.mean[idx])]
    starts = np.array([g[0] for g in np.array_split(np.arange(idx.size), NOISE_BINS)])
    nu, w = s.dof[idx], s.mean[idx]
    dof = np.add.reduceat(nu, starts)
    v = np.add.reduceat(nu * s.var[idx], starts) / dof
    a = np.stack([np.ones(starts.size), np.add.reduceat(nu * w, starts) / dof], 1)
    free = [0, 1] if hold is None else [1 - hold]
    lam = np.zeros(2)
    lam[free] = np.linalg.lstsq(a[:, free], v, rcond=None)[0]
    floor = 0.1 * np.repeat(v, np.diff(np.append(starts, idx.size)))  # a μ_i below a tenth of its bin's v: the floor
    for _ in range(4):
        var = 2 * np.add.reduceat(nu * np.maximum(lam[0] + lam[1] * w, floor) ** 2, starts) / dof ** 2
        aw = a[:, free] / np.sqrt(var)[:, None]
        lam[free] = np.linalg.lstsq(aw, v / np.sqrt(var), rcond=None)[0]
    k = starts.size - len(free)
    chi2_red = float(np.sum((v - a @ lam) ** 2 / var)) / k
    widen = chi2_red if chi2_red > chi2.isf(WIDEN_P, k) / k else 1.0
    cov = np.zeros((2, 2))
    cov[np.ix_(free, free)] = np.linalg.inv(aw.T @ aw) * widen
    return lam, cov


def _upper(lam: np.ndarray, cov: np.ndarray, w: np.ndarray) -> np.ndarray:
    """The line's upper 2 σ band at w (the clips' exclusion errs on the side of leaving a pixel out)."""
    x = np.stack([np.ones_like(w), w], 1)
    return lam[0] + lam[1] * w + 2 * np.sqrt(np.maximum(np.einsum("ij,jk,ik->i", x, cov, x), 0.0))


def channel_fit(s: PixelStats, name: str, where: str) -> tuple[np.ndarray, np.ndarray, int, list]:
    """(λ, σ, pixels used, notes): the line of one channel, the pixels near a clip left out; a λ held at 0 keeps
    the σ of its free fit."""
    from scipy.stats import chi2
    keep = ~s.clipped & (s.mean > FIRST_PASS[0]) & (s.mean < FIRST_PASS[1])
    for _ in range(3):
        if keep.sum() < MIN_PIXELS:
            raise FitError(f"{where}: channel {name} has {int(keep.sum())} pixels clear of the clips: expected ≥ "
                           f"{MIN_PIXELS} (a scene with more mid-grey, or a shorter exposure)")
        lam, cov = line_fit(s, keep)
        mu = np.maximum(_upper(lam, cov, s.mean), 1e-30)
        keep = ~s.clipped & (s.below > CLIP_SIGMAS * np.sqrt(mu)) & (s.above > CLIP_SIGMAS * np.sqrt(mu)) & \
            (s.var < mu * chi2.isf(OUTLIER_P, s.dof) / s.dof)
    lam, cov = line_fit(s, keep)
    sig = np.sqrt(np.diag(cov))
    notes = []
    for k, label in ((0, "lambda_read"), (1, "lambda_shot")):
        if lam[k] >= 0:
            continue
        if lam[k] < -NEGATIVE_SIGMAS * sig[k]:
            raise FitError(f"{where}: {label} of channel {name} is {lam[k]:.3g} ± {sig[k]:.2g}, below 0 by "
                           f"{-lam[k] / sig[k]:.1f} σ: expected ≥ 0 (are --black-level and --saturation the "
                           "frames' own? did the scene move?)")
        notes.append(f"{label} of channel {name} fitted {lam[k]:.3g} ± {sig[k]:.2g} (0 within "
                     f"{NEGATIVE_SIGMAS:g} σ): fitted again with it held at 0")
        held, cov = line_fit(s, keep, hold=k)
        lam, sig = held, np.where(np.arange(2) == k, sig, np.sqrt(np.diag(cov)))
    return lam, sig, int(keep.sum()), notes


def fit_noise(folder, black_dn=None, saturation_dn=None) -> NoiseFit:
    """λ per channel from the folder's frames (module doc)."""
    groups = series_files(folder)
    if not groups:
        raise FitError(f"--noise-frames {folder}: no series of 2 or more frames ({', '.join(SUFFIXES)}): expected "
                       "repeated frames of one static scene")
    return fit_series([read_frames(files, black_dn, saturation_dn, "--noise-frames") for files in groups],
                      f"--noise-frames {folder}")


def fit_series(groups: list[list[Frame]], where: str) -> NoiseFit:
    """λ per channel from series of frames of one camera (module doc); `where` names them in a refusal."""
    first = groups[0][0]
    stats = [[] for _ in range(4)]
    for frames in groups:
        f = frames[0]
        if f.kind == "rgb":
            raise FitError(f"{where} {f.path}: a colour image: expected RAW frames (DNG, or grey PNG/TIFF mosaics): "
                           "a demosaiced image's noise is not the sensor's")
        if f.shape != first.shape or f.kind != first.kind:
            raise FitError(f"{where} {f.path}: {f.kind} frames of {f.shape[1]} × {f.shape[0]} px, but "
                           f"{first.path} is {first.kind} of {first.shape[1]} × {first.shape[0]}: expected one camera")
        for c, mask in enumerate(channels(f)):
            stats[c].append(pixel_stats(frames, mask))
    fits = [channel_fit(_join(stats[c]), CHANNEL_NAMES[c], where) for c in range(4)]
    return NoiseFit(np.array([f[0][0] for f in fits]), np.array([f[1][0] for f in fits]),
                    np.array([f[0][1] for f in fits]), np.array([f[1][1] for f in fits]),
                    sum(len(g) for g in groups), len(groups), tuple(f[2] for f in fits), first.black_dn,
                    first.saturation_dn, first.bits, tuple(n for f in fits for n in f[3]))


def sensor_toml(fit: NoiseFit, source: str) -> str:
    """sensor.toml: the Gaussian model with the measured λ (SensorConfig keys; --sensor-config); the same values
    as fit.json (a λ held at 0 is 0 in both)."""

    def arr(a):
        return "[" + ", ".join(f"{float(v):.6g}" for v in a) + "]"
    white = min(int(round(fit.white_dn)), 2 ** fit.bits - 1)
    return (f"# fitted by udc-render fit from {fit.frames} frames in {fit.series} series of {source}\n"
            f"# channels {', '.join(CHANNEL_NAMES)}; var = lambda_read + lambda_shot * w, "
            "w = (DN - black) / (white - black)\n"
            'noise = "gaussian"\nlambda_source = "fixed"\n'
            f"lambda_read = {arr(fit.lambda_read)}\nlambda_shot = {arr(fit.lambda_shot)}\n"
            f"bit_depth = {fit.bits}\nblack_level_dn = {int(round(fit.black_dn))}\nwhite_level_dn = {white}\n")
