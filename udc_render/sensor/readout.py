"""The sensor's read-out arithmetic, one definition for numpy and torch: mean electrons ──► DN.

    q = min(e, CHARGE_CAP_E) · (1 + PRNU z)⁺ + D t,  o = DSNU u + σ_row r + σ_col c    (sensor.fpn)
    poisson:  DN = black + g · min(n + σ_read N + o, FW),  n = Poisson(min(q, poisson_cap_e))
    gaussian: w = min(g q / R, gaussian_cap),  DN = black + R · min(w + N √(λ_read + λ_shot w) + g o / R, g FW / R)
    none:     DN = black + g · min(q + o, FW)
    DN rounded half to even and clipped to [0, white]; dead pixels read black, hot ones min(DN + g q_hot, top)
    Brooks et al. 2019: log λ_shot = lo + (hi − lo) u,  log λ_read = 2.18 log λ_shot + 1.20 + 0.26 z

(sensor.noise, sensor.fpn and sensor.defects explain the model and its sources.) Two callers run it: the
numpy synthesis (sensor.noise.expose, on a mosaic [H, W], its parameters Python floats, its draws from one
numpy Generator in a fixed order) and the online degradation (restore.degrade_sensor, on packed crops
[B, 4, h/2, w/2], its parameters per-crop columns [B, 1, 1, 1] or [B, 4, 1, 1], its draws from a torch
generator per crop on the device, or replayed from the numpy path's). What differs between them is the layout
and where the random numbers come from; what must not differ is the arithmetic, which the tests hold equal
bit for bit in float64. So this module takes the random draws as arrays (Poisson counts, standard normals,
uniforms) and every parameter as a scalar or an array that broadcasts, and writes each formula once against
the array API standard: the namespace is that of the arrays given (array_api_compat.array_namespace), so the
same lines run in numpy and in torch without udc_render importing torch, and without a copy of the model in
restore. The order of operations is part of the definition (a + b + c is not a + (b + c) in floating point).
"""
from __future__ import annotations

import math

from array_api_compat import array_namespace

__all__ = ["BROOKS_LOG_SHOT_RANGE", "BROOKS_READ_INTERCEPT", "BROOKS_READ_SIGMA", "BROOKS_READ_SLOPE",
           "CHARGE_CAP_E", "DEAD", "HOT", "brooks_lambdas", "defect_classes", "finite_electrons", "fpn_gain",
           "fpn_offset_e", "gaussian_cap", "mean_charge_e", "poisson_cap_e", "quantised", "read_gaussian",
           "read_noiseless", "read_poisson", "with_defects"]

# A mean charge beyond this is saturated whatever the gain map (FW ≤ 1e9): capped first so that a huge but finite
# input never overflows to inf (and inf × a zero gain to NaN).
CHARGE_CAP_E = 1e30
BROOKS_LOG_SHOT_RANGE = (math.log(1e-4), math.log(1.2e-2))
BROOKS_READ_SLOPE, BROOKS_READ_INTERCEPT, BROOKS_READ_SIGMA = 2.18, 1.20, 0.26
DEAD, HOT = 1, 2  # defect classes (0: a good pixel)


def finite_electrons(e):
    """e with NaN as 0 and ±inf as ± the dtype's largest value: a huge but finite radiance saturates, never NaN."""
    xp = array_namespace(e)
    top = float(xp.finfo(e.dtype).max)
    return xp.where(xp.isnan(e), xp.zeros_like(e), xp.clip(e, min=-top, max=top))


def fpn_gain(z, prnu):
    """The PRNU gain map (1 + PRNU z)⁺ of standard normals z."""
    xp = array_namespace(z)
    return xp.clip(1.0 + prnu * z, min=0.0)


def fpn_offset_e(u, rows, columns, dsnu_e, row_offset_e, column_offset_e):
    """The offset map o = DSNU u + σ_row r + σ_col c (e⁻) of standard normals u, and r, c broadcast along rows
    and columns."""
    return dsnu_e * u + row_offset_e * rows + column_offset_e * columns


def mean_charge_e(e, gain, dark_e):
    """q = min(e, CHARGE_CAP_E) · gain + D t: the mean charge the shot noise is drawn around (e⁻)."""
    xp = array_namespace(e)
    return xp.minimum(e, CHARGE_CAP_E) * gain + dark_e


def poisson_cap_e(full_well_e, read_noise_e):
    """The mean charge beyond which Poisson(q) + read noise ≥ FW with probability 1 − e^(−hundreds): the draw is
    capped there (numpy's limit on λ, and overflow), the clipped result the same."""
    return 2 * full_well_e + 100 + 40 * read_noise_e


def gaussian_cap(signal_full_well, lambda_read_max, lambda_shot_max):
    """The normalised signal w is capped ≥ 40 σ above g FW / R (= signal_full_well): finite, the clip the same."""
    return 2 * signal_full_well + 1600 * lambda_shot_max + 40 * math.sqrt(lambda_read_max)


def read_poisson(shot_e, normal, read_noise_e, offset_e, full_well_e, g, black):
    """Signal DN (unrounded) of Poisson counts shot_e, with read noise σ_read N (normal None: none) and the
    offset map (None: none), capped at the full well."""
    xp = array_namespace(shot_e)
    n = shot_e if normal is None else shot_e + read_noise_e * normal
    if offset_e is not None:
        n = n + offset_e
    return black + g * xp.minimum(n, full_well_e)


def read_gaussian(q, normal, lambda_read, lambda_shot, offset_e, g, range_dn, full_well_e, black, cap):
    """Signal DN (unrounded) of the heteroscedastic Gaussian model: w = min(g q / R, cap), y = w + N √(λ_read +
    λ_shot w) (+ g o / R), DN = black + R · min(y, g FW / R); λ per site, broadcast to q."""
    xp = array_namespace(q)
    w = xp.minimum(g * q / range_dn, cap)
    y = w + normal * xp.sqrt(lambda_read + lambda_shot * w)
    if offset_e is not None:
        y = y + (g / range_dn) * offset_e
    return black + range_dn * xp.minimum(y, g * full_well_e / range_dn)


def read_noiseless(q, offset_e, full_well_e, g, black):
    """Signal DN (unrounded) without temporal noise: black + g · min(q (+ o), FW)."""
    xp = array_namespace(q)
    return black + g * xp.minimum(q if offset_e is None else q + offset_e, full_well_e)


def quantised(signal_dn, white_dn):
    """DN rounded half to even and clipped to [0, white] (never wraps); the array's dtype kept."""
    xp = array_namespace(signal_dn)
    return xp.clip(xp.round(signal_dn), min=0.0, max=white_dn)


def brooks_lambdas(u, z):
    """(λ_read, λ_shot) of Brooks et al. 2019 from uniforms u on [0, 1) and standard normals z (module doc)."""
    xp = array_namespace(u, z)
    lo, hi = BROOKS_LOG_SHOT_RANGE
    log_shot = lo + (hi - lo) * u
    log_read = BROOKS_READ_SLOPE * log_shot + BROOKS_READ_INTERCEPT + BROOKS_READ_SIGMA * z
    return xp.exp(log_read), xp.exp(log_shot)


def defect_classes(u, dead_fraction, hot_fraction):
    """int8 classes of uniforms u: DEAD where u < dead_fraction, HOT where dead_fraction ≤ u < dead + hot, else 0."""
    xp = array_namespace(u)
    hot = (u >= dead_fraction) & (u < dead_fraction + hot_fraction)
    zero = xp.zeros(u.shape, dtype=xp.int8)
    return xp.where(u < dead_fraction, zero + DEAD, xp.where(hot, zero + HOT, zero))


def with_defects(dn, kind, black_dn, hot_dn, top_dn, white_dn):
    """The quantised DN with dead pixels (kind DEAD) at black and hot ones (HOT) at min(DN + hot_dn, top) rounded
    half to even and clipped to [0, white]."""
    xp = array_namespace(dn)
    level = quantised(xp.minimum(dn + hot_dn, top_dn), white_dn)
    return xp.where(kind == DEAD, xp.zeros_like(dn) + black_dn, xp.where(kind == HOT, level, dn))
