"""What the deconvolution pipeline (DeP) is allowed to know about a display: its kernels and γ.

Kernels: the channel-effective PSFs (camera × D65 weighted, psf.spectral.channel_kernels) of the
display recorded in the capture's capture.json, for the lens recorded in synth.json, in focus,
with the display at the principal plane (d = 0: a display at d > 0 makes the blur field-dependent,
which DeP does not model), sampled at the packed plane's pitch (2 × the sensor pitch), the R kernel
for R, the G kernel for Gr and Gb, B for B. Cached on disk like every kernel (psf.cache).

γ: what the paper's calibration measures (docs/PHYSICS.md §2: a white square with and without the
display), computed from the display: γ_c = gain · T̄_c · τ_c (1 − o_c), with T̄_c the display's
T(λ) averaged over the monitor white seen by camera channel c, τ_c the pixel grid's transmittance
and o_c the energy outside the kernel window, both channel-weighted (psf.spectral.combine). The
glass's own τ⁰(1 − o⁰) is taken as 1 (its window loses < 0.1 %). `udc-render calibrate` recovers
this γ within 0.1 % (T-OLED). measured_gamma_rggb gives the data's own ratio of sums, which on
small frames reads low: the wide kernels carry light out of the frame.
"""
from __future__ import annotations

import functools
import json

import numpy as np

from psf import Lens
from psf.cache import cached
from psf.spectral import channel_kernels
from restore.data import DataError, Pair, load_pair
from udc_render.sensor import mosaic_of
from udc_render.optics.displays import load_display, preset, white_weights
from udc_render.sensor import pack_rggb


def capture_display(pair: Pair):
    """The Display a pair was captured through (preset or the display file it came from)."""
    path = pair.folder / pair.display / "capture.json"
    d = json.loads(path.read_text()).get("display")
    if d is None:
        raise DataError(f"{path}: no display record: DeP needs the display the capture was made through "
                        "(captures written by `udc-render dataset` or `synth` have one)")
    return preset(d["name"]) if d["source"] == "preset" else load_display(d["source"])


@functools.lru_cache(maxsize=8)  # γ and the kernels of one pair read the same KernelSet
def _channel_kernels(pair: Pair, size_px: int | None, use_cache: bool):
    synth = json.loads((pair.folder / "synth.json").read_text())
    sensor = json.loads((pair.folder / pair.display / "capture.json").read_text())["sensor"]
    size = size_px or (synth["kernel_size_px"] // 2) | 1
    if size % 2 == 0:
        raise DataError(f"kernel_px = {size}: expected an odd number of pixels (a centred kernel)")
    ks, _ = cached(channel_kernels, "channel", capture_display(pair).layout, Lens(**synth["lens"]), use_cache,
                   camera=sensor["camera"], illuminant="D65", step_nm=None, pixel_um=2 * float(sensor["pitch_um"]),
                   size_px=size, distance_mm=0.0, precision="float32")
    return ks


def known_kernels_rggb(pair: Pair, size_px: int | None = None, use_cache: bool = True) -> np.ndarray:
    """[4, k, k] unit-sum kernels at the packed-plane pitch for R, Gr, Gb, B (module doc).
    size_px: odd; default half the synthesis kernel (the same field of view)."""
    k = _channel_kernels(pair, size_px, use_cache).kernels.astype(np.float64)
    k = k / k.sum(axis=(1, 2), keepdims=True)
    return np.stack([k[0], k[1], k[1], k[2]]).astype(np.float32)


def known_gamma_rggb(pair: Pair, size_px: int | None = None, use_cache: bool = True) -> np.ndarray:
    """[4] γ per packed channel R, Gr, Gb, B of the pair's display (module doc)."""
    display = capture_display(pair)
    sensor = json.loads((pair.folder / pair.display / "capture.json").read_text())["sensor"]
    ks = _channel_kernels(pair, size_px, use_cache)
    edges = np.arange(400.0, 701.0, 5.0)
    w = white_weights(edges, sensor["camera"])
    t_c = (w @ display.transmission.band_means(edges)) / w.sum(axis=1)
    g = display.gain * t_c * ks.transmittance * (1 - ks.energy_outside)
    return np.array([g[0], g[1], g[1], g[2]])


def measured_gamma_rggb(pairs: list[Pair]) -> np.ndarray:
    """[4] γ per packed channel by regression over `pairs` (module doc)."""
    num, den = np.zeros(4), np.zeros(4)
    for p in pairs:
        packed, gt = load_pair(p)
        y = pack_rggb(mosaic_of(gt))
        num += packed.astype(np.float64).sum(axis=(1, 2))
        den += y.astype(np.float64).sum(axis=(1, 2))
    return num / np.maximum(den, 1e-30)

