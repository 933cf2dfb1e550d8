"""λ_read and λ_shot per RGGB channel from repeated frames (--noise-frames DIR), with the calibration's
estimator (udc_render.calibration.noise.noise_fit: censored-Gaussian variances in intensity bins, weighted
line var = λ_read + λ_shot w; the paper's regression, l.265).

DIR holds the frames of one static scene (any pattern with dark and bright parts); each sub-folder one more
series (another exposure). Per series of N ≥ 2 frames, in normalised units w = (DN − black) / (white −
black): the clean value is the frames' mean, the residual of each frame (frame − mean) · √(N / (N − 1)) (the
mean's own noise taken out of the variance). At most MAX_PIXELS pixels per channel enter the fit (a fixed
random subset). σ of λ: the weighted line's covariance, each bin's variance known to var √(2 / (n − 1)).
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from udc_render.fit.inputs import SUFFIXES, FitError, read_frames
from udc_render.fit.white import CHANNEL_NAMES, channels

MAX_PIXELS = 1_000_000


@dataclass(frozen=True)
class NoiseFit:
    """λ_read, λ_shot (R, Gr, Gb, B) ± σ, the frames and series used, the levels, the bit depth."""
    lambda_read: np.ndarray
    lambda_read_sigma: np.ndarray
    lambda_shot: np.ndarray
    lambda_shot_sigma: np.ndarray
    frames: int
    series: int
    black_dn: float
    white_dn: float
    bits: int

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


def _line_sigma(w: np.ndarray, var: np.ndarray, n: int) -> tuple[float, float]:
    """σ of (λ_read, λ_shot): the weighted line through the bins, var_b known to var_b √(2 / (n_b − 1))."""
    a = np.stack([np.ones_like(w), w], 1) / (var * math.sqrt(2.0 / max(n - 1, 1)))[:, None]
    cov = np.linalg.pinv(a.T @ a)
    return math.sqrt(cov[0, 0]), math.sqrt(cov[1, 1])


def fit_noise(folder, black_dn=None, saturation_dn=None) -> NoiseFit:
    """λ per channel from the folder's frames (module doc)."""
    from udc_render.calibration.noise import NOISE_BINS, noise_fit
    groups = series_files(folder)
    if not groups:
        raise FitError(f"--noise-frames {folder}: no series of 2 or more frames ({', '.join(SUFFIXES)}): expected "
                       "repeated frames of one static scene")
    w_all, r_all, first = [[] for _ in range(4)], [[] for _ in range(4)], None
    for files in groups:
        frames = read_frames(files, black_dn, saturation_dn, "--noise-frames")
        first = first or frames[0]
        if frames[0].kind == "rgb":
            raise FitError(f"--noise-frames {files[0]}: a colour image: expected RAW frames (DNG, or grey PNG/TIFF "
                           "mosaics): a demosaiced image's noise is not the sensor's")
        span = first.saturation_dn - first.black_dn
        stack = np.stack([(f.dn - f.black_dn) / span for f in frames])
        mean = stack.mean(axis=0)
        resid = (stack - mean) * math.sqrt(len(frames) / (len(frames) - 1))
        for c, mask in enumerate(channels(frames[0])):
            w_all[c].append(np.broadcast_to(mean[mask], (len(frames), int(mask.sum()))).ravel())
            r_all[c].append(resid[:, mask].ravel())
    rng = np.random.default_rng(0)
    fits, sig = [], []
    for c in range(4):
        w, r = np.concatenate(w_all[c]), np.concatenate(r_all[c])
        if w.size > MAX_PIXELS:
            keep = rng.choice(w.size, MAX_PIXELS, replace=False)
            w, r = w[keep], r[keep]
        f = noise_fit(w, r)
        fits.append(f)
        sig.append(_line_sigma(np.asarray(f["w"]), np.asarray(f["var"]), w.size // NOISE_BINS))
    lr = np.array([f["lambda_read"] for f in fits])
    ls = np.array([f["lambda_shot"] for f in fits])
    return NoiseFit(lr, np.array([s[0] for s in sig]), ls, np.array([s[1] for s in sig]),
                    sum(len(g) for g in groups), len(groups), first.black_dn, first.saturation_dn, first.bits)


def sensor_toml(fit: NoiseFit, source: str) -> str:
    """sensor.toml: the Gaussian model with the measured λ (SensorConfig keys; --sensor-config)."""
    arr = lambda a: "[" + ", ".join(f"{max(float(v), 0.0):.6g}" for v in a) + "]"  # noqa: E731
    white = min(int(round(fit.white_dn)), 2 ** fit.bits - 1)
    return (f"# fitted by udc-render fit from {fit.frames} frames in {fit.series} series of {source}\n"
            f"# channels {', '.join(CHANNEL_NAMES)}; var = lambda_read + lambda_shot * w, w = (DN - black) / (white - black)\n"
            'noise = "gaussian"\nlambda_source = "fixed"\n'
            f"lambda_read = {arr(fit.lambda_read)}\nlambda_shot = {arr(fit.lambda_shot)}\n"
            f"bit_depth = {fit.bits}\nblack_level_dn = {int(round(fit.black_dn))}\nwhite_level_dn = {white}\n")
