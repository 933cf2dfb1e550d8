"""Optics stage: apply PSF kernels to rendered band images (docs/PHYSICS.md §1, §3, §4). Per band k:

    y_k = g_k · (x_k ⊗ k_k)  [+ T(λ_k) · transmittance_k · (x̄_k ⊗ f_k)],
    g_k = T(λ_k) · transmittance_k · (1 − energy_outside_k)

- Light that the PSF sends outside the kernel window (energy_outside) is not renormalised: it is lost, or,
  given a far field (optics.far_field), laid on the sensor at a coarse pitch within the lens's acceptance.
- Glass (no display): pass the bare-lens KernelSet (transmittance 1) and transmission None (T = 1).
- d = 0 (or no field kernels): one kernel per band (optics.convolution); d > 0: field phases blended
  (optics.field) with the exact transmitted power at every pixel (optics.field_power); very bright pixels
  convolved apart in float64 (optics.bright).
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from udc_render.optics.bright import BrightPixels
from udc_render.optics.convolution import OpticsError, _check_margin, _precision, convolve_bands, fft_shape
from udc_render.optics.far_field import FarField, far_light
from udc_render.optics.field import FieldBasis, convolve_field, field_weights
from udc_render.optics.field_planes import convolve_field_planes, planes_bound
from udc_render.optics.field_power import PowerMap, field_power_map, stored_or_fresh
from udc_render.optics.primaries import Primaries, convolve_primaries, far_light_primaries

PITCH_RTOL = 1e-6


@dataclass(frozen=True)
class OpticsResult:
    """Irradiance at the sensor per band, sensor frame only.

    images          [K, H, W] float32, same units as the band images × (dimensionless gains);
                    [C, H, W] channel sums Σ_k w_ck y_k when apply_kernels was given channel_weights
    pitch_um        sensor-plane pixel pitch of images
    wavelengths_nm  [K] kernel wavelengths
    gains           [K] g_k = transmission_k · transmittance_k · (1 − energy_outside_k)
    transmission    [K] display spectral transmission T(λ_k) that was applied
    applied         what was done: model, blend, precision, fft_shape, margin_px, kernel_px, phases, ...
    """
    images: np.ndarray
    pitch_um: float
    wavelengths_nm: np.ndarray
    gains: np.ndarray
    transmission: np.ndarray
    applied: dict = field(default_factory=dict)


def _check_finite(bands: np.ndarray, names=None, primaries: Primaries | None = None) -> None:
    """A one-line error naming the first band with a NaN or an infinity (a band's float64 sum is finite exactly
    when its float32 values are: one pass, no mask). Bands made of three planes (primaries) are finite when the
    planes and the matrix are and |x_k| ≤ Σ_c |M_ck| max|r_c| stays inside float32's range: 3 planes checked, not K
    bands."""
    if primaries is not None and _planes_bounded(primaries):
        return
    bad = ~np.isfinite(bands.sum(axis=(1, 2), dtype=np.float64))
    if bad.any():
        k = int(np.argmax(bad))
        name = names[k] if names is not None else f"band {k}"
        n = int((~np.isfinite(bands[k])).sum())
        raise OpticsError(f"{name} (index {k}) holds {n} NaN or infinite value(s); the optics need finite input")


def _planes_bounded(p: Primaries) -> bool:
    """Finite planes and matrix whose bands' bound Σ_c |M_ck| max|r_c| is below half float32's largest value."""
    with np.errstate(invalid="ignore", over="ignore"):  # a NaN or an infinity: the bands' own check names it
        bound = np.abs(np.asarray(p.matrix, np.float64)).T @ p.peaks
    return bool(np.all(np.isfinite(bound)) and bound.max() < 0.5 * np.finfo(np.float32).max)


def _transmission(transmission, K: int) -> np.ndarray:
    t = np.ones(K) if transmission is None else np.asarray(transmission, dtype=np.float64)
    t = np.broadcast_to(t, (K,)).astype(np.float64) if t.ndim == 0 else t
    if t.shape != (K,) or not np.all(np.isfinite(t)) or np.any(t < 0):
        raise OpticsError(f"transmission must be None, a scalar or [K={K}] finite values ≥ 0, "
                          f"got shape {t.shape}")
    return t



def far_field_images(bands: np.ndarray, far_field: FarField, margin_px: int, far_gains: np.ndarray,
                     channel_weights=None, blocks: dict | None = None) -> np.ndarray:
    """The far field's light on the frame (optics.far_field.far_light) with gains T τ [K]: per band [K, h, w],
    or the channel sums [C, h, w] with channel_weights [C, K]; blocks: far_light's block means, kept between calls."""
    w = np.diag(far_gains) if channel_weights is None else np.asarray(channel_weights, float) * far_gains[None, :]
    return far_light(bands, far_field, margin_px, w, blocks)


def _field_through_planes(primaries: Primaries, field_planes: tuple, basis: FieldBasis, gains, channel_weights,
                          margin_px: int, precision: str, workers, applied: dict) -> tuple[np.ndarray, float]:
    """The rank-r blend through the planes at J shared maps (optics.field_planes), its record in applied."""
    pb, J = field_planes
    J = min(int(J), pb.maps.shape[0])
    images = convolve_field_planes(primaries.planes, primaries.matrix, pb, basis, gains, channel_weights, margin_px,
                                   J, precision, workers)
    bound = planes_bound(pb, np.asarray(channel_weights, float), gains, primaries.matrix, primaries.peaks)
    tail = pb.values.clip(0.0)
    applied["field_planes"] = {
        "maps": J, "forward_ffts": 3 * J, "stored_maps": int(pb.maps.shape[0]),
        "map_residual": float(np.sqrt(tail[J:].sum() / tail.sum())) if tail.sum() > 0 else 0.0,
        "bound_e": float(bound[J]),
        "rule": "the K·r weight maps in one basis through the monitor's 3 planes (optics.field_planes); map_residual: "
                "the weighted maps' relative Frobenius residual; bound_e: a bound on any pixel's change"}
    return images, max(basis.residuals)


def apply_kernels(band_image, kernel_set, transmission=None, precision: str = "float32", workers: int | None = None,
                  blend: str = "source", field: bool = True, distance_mm: float | None = None,
                  image_distance_um: float | None = None, period_um=None,
                  field_rank: int | None = None, channel_weights=None, spectra: np.ndarray | None = None,
                  field_basis: FieldBasis | None = None, bright: BrightPixels | None = None,
                  far_field: FarField | None = None, power_map: PowerMap | None = None,
                  kernel_spectra=None, far_blocks: dict | None = None,
                  primaries: Primaries | None = None, field_planes: tuple | None = None) -> OpticsResult:
    """Sensor irradiance per band from a udc_render.render.BandImage and a psf.KernelSet.

    y_k = T(λ_k) · transmittance_k · (1 − energy_outside_k) · (x_k ⊗ k_k), frame cropped (optics.convolution).
    transmission: T(λ_k), None (= 1, T-OLED flat or glass), a scalar, or [K].
    field: use field kernels when the KernelSet has them (d > 0); False forces the mean kernel.
    distance_mm, image_distance_um, period_um (x, y): override the KernelSet's d, z_i and display period.
    field_rank: d > 0: a rank-r basis of each band's phase kernels (convolve_field; None: exact).
    channel_weights [C, K]: images are the channel sums Σ_k w_ck y_k [C, H, W] (one inverse FFT per
    channel; blend 'source'); spectra: band_spectra of the band image, shared between calls (d = 0 path).
    field_basis: the kernel set's rank-`field_rank` bases for this grid, made once (field_basis).
    bright: very bright pixels, convolved apart in float64 (optics.bright; pipeline.bright_pixels).
    far_field: the light past the kernel window, added at a coarse pitch (optics.far_field; None: lost).
    power_map: the exact-power map of this kernel set on this grid, made once (PowerMap.stored; None: made here).
    kernel_spectra: the kernels' spectra at this grid's FFT shape, made once (convolution.kernel_spectra): [K, …] of
    the band kernels on the field-independent path, or per band those of field_basis on the field path.
    far_blocks: a dict that keeps the far field's block means of these bands for the next call (far_light).
    primaries: the band image's three planes (optics.primaries; with channel_weights, no bright pixels): the
    field-independent blur and the far field through them (the same numbers, another round-off).
    field_planes: (PlaneBasis, J) of this set's field_basis on this grid: with primaries, the rank-r 'source' blend
    through the planes at the first J shared weight maps (optics.field_planes; the J and its bounds recorded).
    """
    _precision(precision)  # validate early: one-line error for an unknown precision
    bands = np.asarray(band_image.bands)
    if bands.ndim != 3:
        raise OpticsError(f"band image must be [K, H, W], got shape {bands.shape}")
    K, H, W = bands.shape
    edges = np.asarray(band_image.edges_nm, dtype=np.float64)
    wl = np.asarray(kernel_set.wavelengths_nm, dtype=np.float64)
    names = [f"band {0.5 * (edges[k] + edges[k + 1]):g} nm" for k in range(K)] if edges.size == K + 1 else None
    _check_finite(bands, names, primaries)
    if kernel_set.kernels.shape[0] != K or wl.size != K:
        raise OpticsError(f"{K} band images but {kernel_set.kernels.shape[0]} kernels: one kernel per band needed")
    if edges.size == K + 1:
        outside = (wl < edges[:-1] - 1e-9) | (wl > edges[1:] + 1e-9)
        if outside.any():
            k = int(np.argmax(outside))
            raise OpticsError(f"kernel {k} at {wl[k]:g} nm lies outside band {k} [{edges[k]:g}, {edges[k + 1]:g}] nm")
    pitch = float(band_image.pitch_um)
    if not abs(kernel_set.pixel_um - pitch) <= PITCH_RTOL * pitch:
        raise OpticsError(f"kernel pixel {kernel_set.pixel_um:g} µm differs from the band image pitch {pitch:g} µm "
                          f"(relative tolerance {PITCH_RTOL:g}); compute kernels at pixel_um={pitch:g}")
    m = int(band_image.margin_px)
    S = kernel_set.size_px
    _check_margin(m, S, (H, W))
    t = _transmission(transmission, K)
    gains = t * np.asarray(kernel_set.transmittance, float) * (1.0 - np.asarray(kernel_set.energy_outside, float))

    d_mm = float(kernel_set.distance_mm if distance_mm is None else distance_mm)
    applied = {"convolution": "linear, FFT (scipy.fft rfft2), margin cropped", "precision": precision,
               "output": "bands" if channel_weights is None else "channel sums Σ_k w_ck y_k (Fourier space)",
               "fft_shape": list(fft_shape((H, W), S, m)), "margin_px": m, "kernel_px": S,
               "gain": "T · transmittance · (1 − energy_outside)", "distance_mm": d_mm, "workers": workers,
               "bright_pixels": 0 if bright is None else int(bright.mask.sum())}
    through_planes = primaries is not None and channel_weights is not None and bright is None
    has_field = kernel_set.field_kernels is not None or field_basis is not None
    use_field = field and has_field and d_mm > 0
    if not use_field:
        why = ("field kernels disabled" if has_field and not field
               else "d = 0 or no field kernels: one kernel per band")
        applied.update(model="field-independent", skipped=[f"field-dependent blur ({why})"])
        if through_planes:
            images = convolve_primaries(primaries, kernel_set.kernels, m, gains, channel_weights, precision, workers)
        else:
            images = convolve_bands(bands, kernel_set.kernels, m, gains, precision, workers, channel_weights, spectra,
                                    bright, kernel_spectra)
    else:
        wy, wx, geometry = field_weights(kernel_set, (H, W), pitch, d_mm, image_distance_um, period_um)
        power_map = stored_or_fresh(power_map, field_power_map(kernel_set, (H, W), pitch, d_mm,
                                                               geometry["image_distance_um"], geometry["period_um"]))
        planes_ok = (through_planes and field_planes is not None and blend == "source" and field_basis is not None
                     and field_rank is not None)
        if planes_ok:
            images, residual = _field_through_planes(primaries, field_planes, field_basis, gains, channel_weights, m,
                                                     precision, workers, applied)
        else:
            images, residual = convolve_field(bands, kernel_set.field_kernels, kernel_set.field_power, wy, wx, m,
                                              gains, blend, precision, workers, field_rank, channel_weights,
                                              field_basis, bright, power_map, kernel_spectra)
        applied["field_power"] = ("exact series at each pixel's shift (optics.field_power)" if power_map is not None
                                  else "the phases' powers, interpolated (the kernel set has no field_series)")
        if field_rank is not None:
            applied.update(field_rank=int(field_rank), field_rank_kernel_residual=residual)
        applied.update(model="field-dependent", blend=blend, **geometry)
    if far_field is not None:
        far_gains = t * np.asarray(kernel_set.transmittance, float)
        far = (far_light_primaries(primaries, far_field, m, np.asarray(channel_weights, float) * far_gains[None, :],
                                   far_blocks) if through_planes else
               far_field_images(bands, far_field, m, far_gains, channel_weights, far_blocks))
        images = images + far.astype(images.dtype)
        applied["far_field"] = far_field.describe()
    blur_planes = not use_field or "field_planes" in applied
    if through_planes and (far_field is not None or blur_planes):
        what = ("the blur" if blur_planes else "") + (" and " if blur_planes and far_field is not None else "") + (
            "the far field" if far_field is not None else "")
        applied["primaries"] = (f"{what} through the monitor's 3 planes (bands Σ_c M_ck r_c): each channel's kernels "
                                "summed per plane (optics.primaries)")
    return OpticsResult(np.ascontiguousarray(images, dtype=np.float32), pitch, wl.copy(), gains, t, applied)
