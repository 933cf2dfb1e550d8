"""Fraunhofer transforms from a sampled pupil to sensor pixels.

Sensor intensity for unit irradiance on the pupil (Goodman, Fourier Optics, §5):
    I(u) = |U(u)|²,  U(u) = 1/(λz) ∫ g(x) exp(−2πi x·u/(λz)) dx,  ∫ I du = ∫ |g|² dx.
Pixel integration is exact through the autocorrelation R(Δ) = ∫ g(x+Δ) g*(x) dx (the OTF):
    K(u_j) = ∫_pixel I = (ρ/λz)² Σ_Δ R(Δ) sinc(ρΔx/λz) sinc(ρΔy/λz) exp(−2πi Δ·u_j/λz) δxδy,
R from one zero-padded FFT pair, the last sum by a matrix Fourier transform (MFT: two matrix
products, any output pitch, i.e. any non-integer r, no resampling) or by chirp-z. R is
Hermitian, so only lags Δx ≥ 0 are transformed and K = 2 Re(·) with the Δx = 0 column halved.
PixelMFT folds the MFT over the symmetric lags and pixel centres into real products (a quarter of the
operations) and keeps its matrices for every R of one wavelength.
"""
from __future__ import annotations

import numpy as np
import scipy.fft as sfft

__all__ = ["WORKERS", "LAG_TRANSFORMS", "padded_shape", "power_spectrum", "lags_from_power", "autocorrelation_half",
           "PixelMFT", "pixel_kernel", "lag_transform", "point_kernel",
           "point_field"]

WORKERS = -1  # scipy.fft threads: all cores


def padded_shape(shape: tuple[int, int]) -> tuple[int, int]:
    """FFT size holding every lag of an [ny, nx] field's autocorrelation without wrap: ≥ 2n − 1 per axis."""
    ny, nx = shape
    return sfft.next_fast_len(2 * ny - 1), sfft.next_fast_len(2 * nx - 1)


def power_spectrum(g: np.ndarray) -> np.ndarray:
    """|G|² of g zero-padded to padded_shape (real, g's precision). The FFT along x runs over g's
    ny rows only (the padding rows are zero), then along y over every column."""
    ly, lx = padded_shape(g.shape)
    G = sfft.fft(sfft.fft(g, n=lx, axis=1, workers=WORKERS), n=ly, axis=0, workers=WORKERS)
    power = G.real ** 2
    power += G.imag ** 2
    return power


def lags_from_power(power: np.ndarray, shape: tuple[int, int], dx_um: float, dy_um: float) -> np.ndarray:
    """R(Δ) δxδy, Δy = −(ny−1)…(ny−1), Δx = 0…(nx−1), of a power spectrum on padded_shape(shape):
    R = conj(rfft2(|G|²)) δxδy / L² (one real-input FFT)."""
    ny, nx = shape
    ly, lx = power.shape
    R = np.conj(sfft.rfft2(power, workers=WORKERS)) * (dx_um * dy_um / (ly * lx))
    rows = np.arange(-(ny - 1), ny) % ly
    return R[rows, :nx]


def autocorrelation_half(g: np.ndarray, dx_um: float, dy_um: float) -> np.ndarray:
    """R(Δ) δxδy for lags Δy = −(ny−1)…(ny−1), Δx = 0…(nx−1): array [2ny−1, nx].

    One FFT of the zero-padded pupil, |·|², and one real-input FFT (R = conj(FFT(|G|²)) / L²).
    """
    return lags_from_power(power_spectrum(g), g.shape, dx_um, dy_um)


def _phase_matrix(coords_um: np.ndarray, lags: np.ndarray, step_um: float, scale_um: float, dtype):
    return np.exp(-2j * np.pi * np.outer(coords_um, lags * step_um) / scale_um).astype(dtype)


def pixel_kernel(R_half: np.ndarray, dx_um: float, dy_um: float, wavelength_um: float, distance_um: float,
                 pixel_um: float, size_px: int, method: str = "mft", pixel_integration: bool = True,
                 dtype=np.complex128, deapodize: bool = True) -> np.ndarray:
    """Energy on each sensor pixel (size_px², centred at size_px//2) from the half autocorrelation.

    With pixel_integration False, returns ρ² · I(u_j) (point samples, as peer codes compute).
    deapodize divides by sinc²(δx u/λz) sinc²(δy v/λz): an area-weighted raster is the box-filtered
    mask sampled at δ, whose spectrum is the true one times sinc(δν); this restores the high
    diffraction orders to first order (evaluated at the pixel centre, error ~ (ρδ/λz)²).
    method 'mft' runs PixelMFT (build it once to reuse its matrices over many R); 'czt' chirp-z.
    """
    if method == "mft":
        return PixelMFT(R_half.shape, dx_um, dy_um, wavelength_um, distance_um, pixel_um, size_px,
                        pixel_integration, dtype, deapodize)(R_half)
    nyl, nx = R_half.shape
    ny = (nyl + 1) // 2
    lag_x, lag_y = np.arange(nx), np.arange(-(ny - 1), ny)
    scale = wavelength_um * distance_um
    c = R_half.astype(dtype, copy=True)
    if pixel_integration:
        c *= np.sinc(pixel_um * lag_y * dy_um / scale)[:, None].astype(c.real.dtype)
        c *= np.sinc(pixel_um * lag_x * dx_um / scale)[None, :].astype(c.real.dtype)
    c[:, 0] *= 0.5
    u = (np.arange(size_px) - size_px // 2) * pixel_um
    k = lag_transform(c, lag_y, lag_x, dy_um, dx_um, u, scale, method, dtype)
    k = 2.0 * k.real.astype(np.float64) * (pixel_um / scale) ** 2 * dx_um * dy_um
    return _deapodize(k, u, dx_um, dy_um, scale) if deapodize else k


def _folded_matrices(u_um: np.ndarray, n: int, step_um: float, scale_um: float, pixel_um: float, rdtype):
    """cos(θ_j m) w_m and sin(θ_j m) w_m, θ_j = 2π step u_j / scale, lags m = 0…n−1, w_m the pixel
    sinc(ρ m step / scale) (pixel_um = 0: w = 1): [len(u), n] each."""
    m = np.arange(n)
    theta = 2 * np.pi * np.outer(u_um, m * step_um) / scale_um
    w = np.sinc(pixel_um * m * step_um / scale_um)
    return (np.cos(theta) * w).astype(rdtype), (np.sin(theta) * w).astype(rdtype)


def _real_matmul(a: np.ndarray, z: np.ndarray) -> np.ndarray:
    """a @ z for real a and complex z, as one real matrix product over z's interleaved (re, im) columns."""
    z = np.ascontiguousarray(z)
    return (a @ z.view(a.dtype)).view(z.dtype)


class PixelMFT:
    """pixel_kernel's MFT at one wavelength, its matrices built once and applied to any number of
    half autocorrelations [2ny−1, nx] (the field phases of one λ share them).

    Folded over the symmetric lags and pixel centres (u_{−j} = −u_j, θ_j = 2π δ u_j / λz):
        Σ_m c_m e^{∓iθ_j m} = Σ_{m≥0} cos(θ_j m) e_m ∓ i Σ_{m>0} sin(θ_j m) o_m,  e_m, o_m = c_m ± c_{−m},
    along y, then K(v, ±u) = 2 Re(A e^{∓iθ n}) = 2 (Re A · cos ± Im A · sin) along x: real matrix
    products over u ≥ 0 only, a quarter of the operations of the complex MFT, same result.
    """

    def __init__(self, lag_shape: tuple[int, int], dx_um: float, dy_um: float, wavelength_um: float,
                 distance_um: float, pixel_um: float, size_px: int, pixel_integration: bool = True,
                 dtype=np.complex128, deapodize: bool = True):
        nyl, nx = lag_shape
        scale = wavelength_um * distance_um
        rdtype = np.finfo(dtype).dtype
        u = np.arange(size_px // 2 + 1) * pixel_um
        rho = pixel_um if pixel_integration else 0.0
        self.cos_y, self.sin_y = _folded_matrices(u, (nyl + 1) // 2, dy_um, scale, rho, rdtype)
        self.cos_x, self.sin_x = _folded_matrices(u, nx, dx_um, scale, rho, rdtype)
        self.cos_x[:, 0] *= 0.5  # the Δx = 0 column counts once in K = 2 Re(·)
        self.factor = 2.0 * (pixel_um / scale) ** 2 * dx_um * dy_um
        full = (np.arange(size_px) - size_px // 2) * pixel_um
        self.deapodize = (lambda k: _deapodize(k, full, dx_um, dy_um, scale)) if deapodize else None

    def __call__(self, R_half: np.ndarray) -> np.ndarray:
        """The kernel of a half autocorrelation [2ny−1, nx] (autocorrelation_half)."""
        ny = self.cos_y.shape[1]
        return self._folded(R_half[ny - 1:ny], R_half[ny:], R_half[ny - 2::-1], 1.0, False)

    def of_power(self, power: np.ndarray, dx_um: float, dy_um: float) -> np.ndarray:
        """The kernel of a padded power spectrum |G|² (power_spectrum), from F = rfft2(|G|²) as it stands:
        R(m) = conj(F_m) δxδy / L², the conjugate and the scale applied after the (real) matrix products."""
        ly, lx = power.shape
        ny, nx = self.cos_y.shape[1], self.cos_x.shape[1]
        F = sfft.rfft2(power, workers=WORKERS)
        return self._folded(F[:1, :nx], F[1:ny, :nx], F[ly - 1:ly - ny:-1, :nx], dx_um * dy_um / (ly * lx), True)

    def _folded(self, zero, pos, neg, scale: float, conj: bool) -> np.ndarray:
        """The kernel of lags 0, +m and −m (rows, m = 1…ny−1; their conjugates when conj) × scale."""
        even = np.empty((pos.shape[0] + 1, pos.shape[1]), pos.dtype)
        even[0] = zero[0]
        np.add(pos, neg, out=even[1:])
        t1 = _real_matmul(self.cos_y, even)                              # [h+1, nx], rows u ≥ 0
        t2 = _real_matmul(self.sin_y[:, 1:], pos - neg)
        if conj:
            t1, t2 = np.conj(t1), np.conj(t2)
        back = slice(-1, 0, -1)                                          # rows u = hρ … ρ, for −u
        re = np.concatenate([t1.real[back] - t2.imag[back], t1.real + t2.imag])
        im = np.concatenate([t1.imag[back] + t2.real[back], t1.imag - t2.real])
        c, s = re @ self.cos_x.T, im @ self.sin_x.T                      # [S, h+1]
        k = np.concatenate([(c - s)[:, back], c + s], axis=1).astype(np.float64) * (self.factor * scale)
        return self.deapodize(k) if self.deapodize else k


def _deapodize(k: np.ndarray, u_um: np.ndarray, dx_um: float, dy_um: float, scale_um: float) -> np.ndarray:
    """Divide by the box filter's sinc², clamped at its value at the alias-free edge (|δu/λz| = ½):
    beyond it the raster's spectrum is alias, and an unclamped 1/sinc² would amplify it without bound."""
    floor = np.sinc(0.5) ** 2
    wy = np.maximum(np.sinc(dy_um * u_um / scale_um) ** 2, floor)
    wx = np.maximum(np.sinc(dx_um * u_um / scale_um) ** 2, floor)
    return k / np.outer(wy, wx)


def _mft_lags(c: np.ndarray, lags: np.ndarray, step_um: float, u_um: np.ndarray, scale_um: float, axis: int,
              dtype=np.complex128) -> np.ndarray:
    """Σ_m c_m exp(−2πi m·step·u_j/scale) along `axis` by a matrix product with E_jm (N·S² operations)."""
    e = _phase_matrix(u_um, lags, step_um, scale_um, dtype)
    return e @ c if axis == 0 else c @ e.T


def _czt_lags(c: np.ndarray, lags: np.ndarray, step_um: float, u_um: np.ndarray, scale_um: float, axis: int,
              dtype=np.complex128) -> np.ndarray:
    """Σ_m c_m exp(−2πi m·step·u_j/scale) along `axis` for uniform u_j, by Bluestein's chirp-z
    (N log N operations; dtype unused: scipy's czt keeps the input's precision).

    lags is any arithmetic progression of unit step (integers, or pupil coordinates / δ)."""
    alpha = step_um * (u_um[1] - u_um[0]) / scale_um
    c0 = u_um[0] / (u_um[1] - u_um[0])  # u_j = (j + c0)·Δu
    w = np.exp(-2j * np.pi * alpha)
    a = np.exp(2j * np.pi * alpha * c0)
    from scipy.signal import czt  # here: scipy.signal costs every process that imports psf ~1 s
    out = czt(c, m=u_um.size, w=w, a=a, axis=axis)
    post = np.exp(-2j * np.pi * lags[0] * step_um * u_um / scale_um)
    shape = [1, 1]
    shape[axis] = -1
    return out * post.reshape(shape).astype(out.dtype)


# One signature: (c, lags, step_um, u_um, scale_um, axis, dtype) → c transformed along `axis` to u_um.
LAG_TRANSFORMS = {"mft": _mft_lags, "czt": _czt_lags}


def lag_transform(c: np.ndarray, lags_y: np.ndarray, lags_x: np.ndarray, dy_um: float, dx_um: float,
                  u_um: np.ndarray, scale_um: float, method: str, dtype=np.complex128) -> np.ndarray:
    """F[j, i] = Σ_{m,n} c[m, n] exp(−2πi (m·δy·u_j + n·δx·u_i)/scale): rows (y) first, then columns (x)."""
    if method not in LAG_TRANSFORMS:
        raise ValueError(f"method must be one of {', '.join(LAG_TRANSFORMS)}, got '{method}'")
    transform = LAG_TRANSFORMS[method]
    return transform(transform(c, lags_y, dy_um, u_um, scale_um, 0, dtype), lags_x, dx_um, u_um, scale_um, 1, dtype)


def point_kernel(g: np.ndarray, x_um: np.ndarray, y_um: np.ndarray, dx_um: float, dy_um: float,
                 wavelength_um: float, distance_um: float, pixel_um: float, size_px: int, method: str = "mft",
                 dtype=np.complex128, deapodize: bool = True) -> np.ndarray:
    """ρ² · I(u_j) at the pixel centres by a direct MFT (or chirp-z) of the pupil field.

    The point-sampled kernel, as peer codes (hcipy, poppy) compute it: N²S + NS² operations per
    wavelength, half of the autocorrelation route, which is only needed for pixel integration.
    """
    scale = wavelength_um * distance_um
    u = (np.arange(size_px) - size_px // 2) * pixel_um
    g = g.astype(dtype, copy=False)
    U = lag_transform(g, y_um / dy_um, x_um / dx_um, dy_um, dx_um, u, scale, method, dtype)
    k = (np.abs(U) ** 2).astype(np.float64) * (dx_um * dy_um / scale) ** 2 * pixel_um ** 2
    return _deapodize(k, u, dx_um, dy_um, scale) if deapodize else k


def point_field(g: np.ndarray, x_um: np.ndarray, y_um: np.ndarray, dx_um: float, dy_um: float,
                wavelength_um: float, distance_um: float, u_um: np.ndarray, v_um: np.ndarray) -> np.ndarray:
    """Complex field U(v_i, u_j) at arbitrary sensor points by MFT: [len(v), len(u)]."""
    scale = wavelength_um * distance_um
    ex = np.exp(-2j * np.pi * np.outer(u_um, x_um) / scale)
    ey = np.exp(-2j * np.pi * np.outer(v_um, y_um) / scale)
    return ey @ g @ ex.T * (dx_um * dy_um / scale)
