"""What the deconvolution pipeline (DeP) is allowed to know about a display: its kernels and γ.

Kernels (DEP_KERNELS), of the display recorded in the capture's capture.json, for the lens recorded in
synth.json, in focus, with the display at the principal plane (d = 0: a display at d > 0 makes the blur
field-dependent, which DeP does not model), sampled at the packed plane's pitch (2 × the sensor pitch),
the R kernel for R, the G kernel for Gr and Gb, B for B, cached on disk like every kernel (psf.cache):
- 'paper' (the default, the row 'dep'): the paper's computed PSF, "the pre-computed PSF" its DeP used
  (l.277): its recipe as printed at 640 / 520 / 450 nm (psf.paper; `udc-render psf --method paper`),
  the kernels of the paper profile's synthesis, for the diffraction-limited lens (its model has no lens
  aberrations, l.145–171: a lens's zernike_waves in synth.json are dropped). On `physical` captures it is
  the misfit the paper's DeP "suffers from" (l.410);
- 'exact' (the row 'dep_exact', "DeP (exact kernel)"): the channel-effective PSFs of the camera's
  sensitivities under D65 (psf.spectral.channel_kernels): the kernels of the per-channel synthesis with
  camera kernels, and the closest channel kernels to the spectral form's band kernels at d = 0, with the
  lens's aberrations; the upper bound a good PSF gives.

γ: the γ that made the capture, by the one definition (udc_render.optics.gamma, what the paper's
calibration measures): for the spectral form, band-wise from the display's and the bare lens's band
kernels on the synthesis grid recorded in synth.json (loaded from the kernel cache the synthesis
filled), weighted by the rendered monitor white; for the per-channel form, the γ recorded in
capture.json. `udc-render calibrate` recovers it within 0.1 % (T-OLED). measured_gamma_rggb gives
the data's own ratio of sums, which on small frames reads low: the wide kernels carry light out of
the frame.
"""
from __future__ import annotations

import functools
import json
from dataclasses import replace

import numpy as np

from psf import Lens
from restore.data import DataError, Pair, load_pair
from udc_render.description import packed_window
from udc_render.optics.displays import load_display, preset
from udc_render.optics.gamma import display_gamma
from udc_render.pipeline import SynthConfig, band_kernel_set
from udc_render.scene.geometry import RenderGrid
from udc_render.sensor import mosaic_of, pack_rggb, rgb_to_rggb
from udc_render.synth_kernels import camera_channel_kernels, paper_channel_kernels


def capture_display(pair: Pair):
    """The Display a pair was captured through (preset or the display file it came from)."""
    path = pair.folder / pair.display / "capture.json"
    d = json.loads(path.read_text()).get("display")
    if d is None:
        raise DataError(f"{path}: no display record: DeP needs the display the capture was made through "
                        "(captures written by `udc-render dataset` or `synth` have one)")
    return preset(d["name"]) if d["source"] == "preset" else load_display(d["source"])


DEP_KERNELS = ("paper", "exact")  # module doc


@functools.lru_cache(maxsize=8)  # γ and the kernels of one pair read the same KernelSet
def _channel_kernels(pair: Pair, size_px: int | None, use_cache: bool, source: str = "paper"):
    if source not in DEP_KERNELS:
        raise DataError(f"DeP kernels = {source!r}: expected one of {', '.join(DEP_KERNELS)}")
    synth = json.loads((pair.folder / "synth.json").read_text())
    sensor = json.loads((pair.folder / pair.display / "capture.json").read_text())["sensor"]
    size = size_px or (synth["kernel_size_px"] // 2) | 1
    if size % 2 == 0:
        raise DataError(f"kernel_px = {size}: expected an odd number of pixels (a centred kernel)")
    layout, lens, pitch_um = capture_display(pair).layout, Lens(**synth["lens"]), float(sensor["pitch_um"])
    if source == "paper":  # the paper's diffraction model: no lens aberrations (module doc)
        return packed_paper_kernels(layout, replace(lens, zernike_waves=()), pitch_um, size, use_cache)
    return packed_channel_kernels(layout, lens, sensor["camera"], pitch_um, size, use_cache)


def packed_paper_kernels(layout, lens: Lens, sensor_pitch_um: float, size_px: int, use_cache: bool = True):
    """The paper's computed PSF [3] of `layout` at the packed planes' pitch (2 × sensor_pitch_um), size_px
    odd (udc_render.synth_kernels.paper_channel_kernels; module doc)."""
    return paper_channel_kernels(layout, lens, 2 * float(sensor_pitch_um), size_px, use_cache)


def packed_channel_kernels(layout, lens: Lens, camera: str, sensor_pitch_um: float, size_px: int,
                           use_cache: bool = True):
    """The channel-effective KernelSet [3] (R, G, B; camera × D65, d = 0) of `layout` at the packed
    planes' pitch (2 × sensor_pitch_um), size_px odd (udc_render.synth_kernels.camera_channel_kernels)."""
    return camera_channel_kernels(layout, lens, camera, 2 * float(sensor_pitch_um), size_px, use_cache)


def rggb_stack(kernels: np.ndarray) -> np.ndarray:
    """[4, k, k] float32 R, Gr, Gb, B from channel kernels [3, k, k] (R, G, B), each normalised to unit sum
    (in float64): both greens take G."""
    k = np.asarray(kernels, np.float64)
    k = k / k.sum(axis=(1, 2), keepdims=True)
    return np.stack([k[0], k[1], k[1], k[2]]).astype(np.float32)


def rggb_kernels(kernel_set) -> np.ndarray:
    """[4, k, k] float32 unit-sum kernels R, Gr, Gb, B from a channel KernelSet [3] (R, G, B)."""
    return rggb_stack(kernel_set.kernels)


def packed_from_sensor(kernels: np.ndarray) -> np.ndarray:
    """[4, k, k] float32 unit-sum kernels R, Gr, Gb, B at the packed planes' pitch from channel kernels
    [3, S, S] (R, G, B; S odd, centre c = S // 2) at the sensor pitch, such as a kernel bank's: each integrated over a
    packed pixel (2 × 2 sensor pixels) centred on the kernel's centre and sampled every 2 pixels,
        k[i, j] = Σ_{a, b ∈ {−1, 0, 1}} h(a) h(b) K[c + 2i + a, c + 2j + b],  h = (½, 1, ½),  |i|, |j| ≤ c // 2,
    then normalised: a sensor-pitch delta becomes a packed delta, a shift of 2 px one of 1 px."""
    k = np.asarray(kernels, np.float64)
    if k.ndim != 3 or k.shape[0] != 3 or k.shape[1] != k.shape[2] or k.shape[1] % 2 == 0:
        raise DataError(f"kernels: shape {k.shape}: expected [3, S, S] (R, G, B) with S odd")
    c = k.shape[1] // 2  # the one definition: udc_render.description.packed_window, every packed pixel kept
    return rggb_stack(packed_window(k, 2 * (c // 2) + 1, normalise=False)[0])


def known_kernels_rggb(pair: Pair, size_px: int | None = None, use_cache: bool = True,
                       source: str = "paper") -> np.ndarray:
    """[4, k, k] unit-sum kernels at the packed-plane pitch for R, Gr, Gb, B; `source`: DEP_KERNELS
    (module doc). size_px: odd; default half the synthesis kernel (the same field of view)."""
    return rggb_kernels(_channel_kernels(pair, size_px, use_cache, source))


def known_gamma_rggb(pair: Pair, use_cache: bool = True) -> np.ndarray:
    """[4] γ per packed channel R, Gr, Gb, B of the pair's display: the γ that made the capture
    (module doc)."""
    display = capture_display(pair)
    capture = json.loads((pair.folder / pair.display / "capture.json").read_text())
    if "gamma_rgb" in capture:  # the per-channel form scaled by this γ
        return np.array(rgb_to_rggb(capture["gamma_rgb"]), float)
    synth = json.loads((pair.folder / "synth.json").read_text())
    render = synth["render"]
    edges = np.asarray(render["band_edges_nm"], float)
    grid = RenderGrid(float(synth["kernel_pixel_um"]), (int(synth["kernel_size_px"]) - 1) // 2, tuple(edges))
    s = render["sensor"]
    frame_um = (s["width_px"] * s["pitch_um"], s["height_px"] * s["pitch_um"])
    lens, cfg = Lens(**synth["lens"]), SynthConfig(kernel_precision=synth["kernel_precision"], use_cache=use_cache)
    ks = band_kernel_set(display.layout, lens, grid, display.distance_mm, frame_um, cfg)
    glass = band_kernel_set(None, lens, grid, 0.0, frame_um, cfg)
    matrix = render.get("band_matrix")
    white = np.asarray(matrix, float).sum(axis=0) if matrix is not None else np.ones(edges.size - 1)
    return np.array(rgb_to_rggb(display_gamma(display, ks, glass, edges, capture["sensor"]["camera"], white)))


def measured_gamma_rggb(pairs: list[Pair]) -> np.ndarray:
    """[4] γ per packed channel by regression over `pairs` (module doc)."""
    num, den = np.zeros(4), np.zeros(4)
    for p in pairs:
        packed, gt = load_pair(p)
        y = pack_rggb(mosaic_of(gt))
        num += packed.astype(np.float64).sum(axis=(1, 2))
        den += y.astype(np.float64).sum(axis=(1, 2))
    return num / np.maximum(den, 1e-30)

