"""The PSF study's error metrics: kernel differences against a reference, and the comparisons each
knob's job runs on its KernelSet (field phases interpolated between phases, kernel windows cropped)."""
from __future__ import annotations

import warnings

import numpy as np


def kernel_errors(k, k_ref) -> tuple[float, float]:
    """(max over channels of Σ|k − k_ref|, max over channels of max|k − k_ref| / max k_ref)."""
    k = np.asarray(k, dtype=np.float64).reshape(-1, *np.shape(k)[-2:])
    r = np.asarray(k_ref, dtype=np.float64).reshape(-1, *np.shape(k_ref)[-2:])
    d = np.abs(k - r)
    l1 = d.sum(axis=(-2, -1))
    rel = d.max(axis=(-2, -1)) / r.max(axis=(-2, -1))
    return float(l1.max()), float(rel.max())


def crop_centre(k: np.ndarray, size: int) -> np.ndarray:
    """The size² centre of [..., S, S] kernels centred at S // 2 (size odd)."""
    s = k.shape[-1]
    lo = s // 2 - size // 2
    return k[..., lo:lo + size, lo:lo + size]


def periodic_bilinear(samples: np.ndarray, p_ref: int) -> np.ndarray:
    """Resample [P, P, ...] samples at shifts a/P (a = 0…P−1, periodic) onto the p_ref grid b/p_ref.

    Periodic bilinear interpolation between phases: what a renderer holding P phases would use
    at an image position between them. Returns [p_ref, p_ref, ...].
    """
    P = samples.shape[0]
    t = np.arange(p_ref) / p_ref * P
    i0 = np.floor(t).astype(int) % P
    i1 = (i0 + 1) % P
    w = t - np.floor(t)
    out = np.zeros((p_ref, p_ref) + samples.shape[2:])
    for jj in range(p_ref):
        for ii in range(p_ref):
            acc = 0.0
            for jy, wy in ((i0[jj], 1 - w[jj]), (i1[jj], w[jj])):
                for ix, wx in ((i0[ii], 1 - w[ii]), (i1[ii], w[ii])):
                    if wy * wx:
                        acc = acc + wy * wx * samples[jy, ix].astype(np.float64)
            out[jj, ii] = acc
    return out


def basic_errors(ks, ref_kernels) -> dict:
    """error_L1 and error_max_rel (kernel_errors) against ref_kernels, and the run's max energy_outside."""
    l1, rel = kernel_errors(ks.kernels, ref_kernels)
    return {"error_L1": l1, "error_max_rel": rel, "energy_outside": float(np.max(ks.energy_outside))}


def banding_amplitude(ks) -> float:
    """max |field_power − 1| over the phases (0 without field phases)."""
    return float(np.max(np.abs(ks.field_power - 1.0))) if ks.field_power is not None else 0.0


def compare_with_aux(get_ref_kernels, aux_fn):
    """Error against the shared reference, plus L1_same_N_ref against aux_fn()'s kernels (untimed).

    aux_fn is an isolating reference at the run's own pupil sampling (the float64 MFT run at the
    same N: for the precision knob and for the paper recipe).
    """
    def compare(ks):
        out = basic_errors(ks, get_ref_kernels())
        if aux_fn is not None:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                aux = aux_fn().kernels
            out["L1_same_N_ref"] = kernel_errors(ks.kernels, aux)[0]
        return out
    return compare


def _whole_period_shifts_um(q: int, period) -> np.ndarray:
    """The q × q shifts (i/q · pitch_x, j/q · pitch_y), [q, q, 2] µm."""
    return np.stack(np.meshgrid(np.arange(q) / q * period[0], np.arange(q) / q * period[1]), axis=-1)


def compare_field(get_ref, p_ref: int):
    """basic_errors of the phase-averaged kernels, and with P phases bilinearly interpolated onto the
    reference's p_ref² shifts: field_kernel_L1_interp = max Σ|k_field − k_field,ref|, banding_err_interp
    = max |field_power − field_power_ref|; banding_err_matched at the coinciding phases (P | p_ref)."""
    def compare(ks):
        r = get_ref()
        out = basic_errors(ks, r.kernels)
        P = ks.field_kernels.shape[1]
        period = np.asarray(r.params["display"].get("pitch_x_um", np.nan)), \
            np.asarray(r.params["display"].get("pitch_y_um", np.nan))
        ours, ref_grid = _whole_period_shifts_um(P, period), _whole_period_shifts_um(p_ref, period)
        if not (np.allclose(ks.field_shifts_um, ours) and np.allclose(r.field_shifts_um, ref_grid)):
            # The engine sampled shifts that are not whole-period fractions (sensor sees < 1 period):
            # the phase grids are not comparable; keep the averaged-kernel error only.
            return out
        fk = periodic_bilinear(ks.field_kernels[0], p_ref)  # [p_ref, p_ref, S, S]
        rk = r.field_kernels[0].astype(np.float64)
        out["field_kernel_L1_interp"] = float(np.abs(fk - rk).sum(axis=(-2, -1)).max())
        fp = periodic_bilinear(ks.field_power[0], p_ref)
        out["banding_err_interp"] = float(np.abs(fp - r.field_power[0]).max())
        if p_ref % P == 0:
            step = p_ref // P
            matched = r.field_power[0][::step, ::step]
            out["banding_err_matched"] = float(np.abs(ks.field_power[0] - matched).max())
        return out
    return compare


def compare_size(get_ref):
    """The S² kernel against the reference's S² centre crop renormalised to unit sum (error_L1,
    error_max_rel), and zero-padded against the whole reference (L1_vs_full_ref)."""
    def compare(ks):
        r = get_ref()
        S = ks.size_px
        crop = crop_centre(r.kernels.astype(np.float64), S)
        inside = crop.sum(axis=(-2, -1))
        l1, rel = kernel_errors(ks.kernels, crop / inside[:, None, None])
        full = np.zeros(r.kernels.shape)
        lo = r.size_px // 2 - S // 2
        full[:, lo:lo + S, lo:lo + S] = ks.kernels
        l1_full, _ = kernel_errors(full, r.kernels)
        # The energy outside the S window according to the reference: 1 − (1 − e_ref) Σ crop.
        check = 1.0 - (1.0 - r.energy_outside) * inside
        return {"error_L1": l1, "error_max_rel": rel, "energy_outside": float(np.max(ks.energy_outside)),
                "L1_vs_full_ref": l1_full, "energy_outside_check": float(np.max(check))}
    return compare
