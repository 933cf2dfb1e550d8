"""The diffraction orders' lattice in closed form: where the orders are, hence the display's pitch and
rotation.

A display of cell p_x × p_y in front of a lens of image distance z_i sends order (m, n) of wavelength λ to
    u_mn = u_0 + m e_1 + n e_2,   |e_1| = λ z_i / p_x,  |e_2| = λ z_i / p_y   (paraxial grating equation),
e_1 turned by the display's rotation φ from the sensor's x axis (towards +y, the rows). Steps:
1. peaks: local maxima of the HDR image standing PEAK_SNR σ above the median of their 5 × 5 ring (a spot, not
   a noise bump on the bright wings of a saturated order nor a broad maximum between two), located by an
   iterated centroid in a soft disc of CENTROID_RADIUS_PX (position noise σ_k from the pixels' variances);
   a region saturated in every exposure is
   one peak at its pixels' centroid, brighter than any other (the largest first), used to find the lattice
   but never to solve it (its centroid is as good as its clipped outline);
2. the visible lattice: the two shortest centrosymmetric peak vectors from the brightest (the PSF of a real
   mask at d = 0 is centrosymmetric), Lagrange–Gauss reduced, whose lattice holds 60 % of the brightest 50
   peaks; when it does not, the next pair, the first vector among the shortest BASIS_TRIES (a wing's or
   ring's maxima beside a saturated order make short vectors off the lattice);
3. a family's cell: the visible lattice is N = M U in cell orders (M: the family's visible orders, e.g. the
   pentile's m + n even; U: the reduction's unimodular ambiguity), E = [a b] N⁻¹; the U giving the smallest
   rotation with e_1 ⟂ e_2 (within MAX_SKEW_DEG) is taken;
4. weighted linear least squares of every unsaturated peak on its order (m, n): x_k = x_0 + m e_1x + n e_2x
   (and y), weights 1 / (σ_k² + s²), s the scatter beyond the noise (pixel locking, neighbours' light), solved so
   that χ²/dof = 1; the covariance (AᵀWA)⁻¹ gives the ± of the pitch and rotation by the delta method.
The pitch scales with λ z_i: an error of the focal length passes into it one to one.
"""
from __future__ import annotations

import itertools
import math
from dataclasses import dataclass

import numpy as np

from udc_render.fit.inputs import FitError

PEAK_SNR = 6.0
MAX_PEAKS = 600
CENTROID_RADIUS_PX = 2.0
MIN_SPACING_PX = 3.0
MAX_ROTATION_DEG, MAX_SKEW_DEG = 30.0, 10.0
ASSIGN_TOLERANCE = 0.2  # of the shortest spacing
BASIS_TRIES = 8


@dataclass(frozen=True)
class Window:
    """The fitted square of the frame: side `size` (odd) centred on pixel (x0, y0); window coordinates have
    that pixel at (0, 0), x along the columns, y along the rows."""
    x0: int
    y0: int
    size: int

    @property
    def half(self) -> int:
        return self.size // 2

    def crop(self, a: np.ndarray) -> np.ndarray:
        h = self.half
        return a[self.y0 - h:self.y0 + h + 1, self.x0 - h:self.x0 + h + 1]


def spot_window(value: np.ndarray, clipped: np.ndarray, size_px: int) -> Window:
    """The window of side ≤ size_px (odd) centred on the spot, shrunk to stay inside the frame: on the median
    of the pixels saturated in every exposure where there are some (their set is centrosymmetric about the
    zeroth order, a few hot pixels aside; the brightest of them can be any saturated order), else on the
    brightest 5 × 5 pixels."""
    from scipy.ndimage import uniform_filter
    if clipped.any():
        ys, xs = np.nonzero(clipped)
        y0, x0 = int(round(float(np.median(ys)))), int(round(float(np.median(xs))))
    else:
        score = uniform_filter(value, 5, mode="constant")
        y0, x0 = np.unravel_index(int(np.argmax(score)), score.shape)
    h, w = value.shape
    half = min(size_px // 2, x0, y0, w - 1 - x0, h - 1 - y0)
    return Window(int(x0), int(y0), 2 * int(max(half, 0)) + 1)


@dataclass(frozen=True)
class Peaks:
    """Local maxima: xy [N, 2] (window px from its centre), sigma [N] (position noise per axis, px), snr [N],
    clipped [N] (a saturated region's centroid: module doc, step 1)."""
    xy: np.ndarray
    sigma: np.ndarray
    snr: np.ndarray
    clipped: np.ndarray


def _centroids(v, var, bad, ys, xs, radius):
    """Iterated centroids in a soft disc (weights clip(radius + ½ − distance, 0, 1)) around integer peaks."""
    r = int(math.ceil(radius)) + 2
    off = np.arange(-r, r + 1)
    vp, varp, badp = (np.pad(a, r, constant_values=c) for a, c in ((v, 0.0), (var, np.inf), (bad, True)))
    iy, ix = ys[:, None, None] + r + off[None, :, None], xs[:, None, None] + r + off[None, None, :]
    pv, pvar, pbad = vp[iy, ix], varp[iy, ix], badp[iy, ix]
    gy, gx = np.broadcast_arrays(off[:, None] + 0.0, off[None, :] + 0.0)
    cx = cy = np.zeros(len(ys))
    for _ in range(4):
        a = np.clip(radius + 0.5 - np.hypot(gx[None] - cx[:, None, None], gy[None] - cy[:, None, None]), 0, 1)
        s = np.sum(a * pv, axis=(1, 2))
        s = np.where(s != 0, s, np.nan)  # a centroid of nothing (a model that is 0 there): NaN, dropped
        cx = np.clip(np.sum(a * pv * gx, axis=(1, 2)) / s, -1.0, 1.0)
        cy = np.clip(np.sum(a * pv * gy, axis=(1, 2)) / s, -1.0, 1.0)
    d2 = (gx[None] - cx[:, None, None]) ** 2 + (gy[None] - cy[:, None, None]) ** 2
    noise = np.sqrt(np.sum(a * a * np.where(np.isfinite(pvar), pvar, 0.0) * d2 / 2, axis=(1, 2))) / s
    masked = np.any(pbad & (a > 0), axis=(1, 2))
    return xs + cx, ys + cy, np.where(masked, np.hypot(noise, 0.3), noise)


def _clipped_regions(clip: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(centroids [K, 2] (x, y, window array px), pixel counts [K]) of the 8-connected saturated regions,
    the largest first."""
    from scipy.ndimage import center_of_mass, label
    labels, k = label(clip, structure=np.ones((3, 3)))
    if k == 0:
        return np.zeros((0, 2)), np.zeros(0, int)
    count = np.bincount(labels.ravel())[1:]
    cy_cx = np.array(center_of_mass(clip, labels, np.arange(1, k + 1))).reshape(-1, 2)
    order = np.argsort(-count, kind="stable")
    return cy_cx[order, ::-1], count[order]


def find_peaks(value, var, usable, clipped, window: Window) -> Peaks:
    """The PSF's local maxima in the window (module doc, step 1): the saturated regions (largest first), then
    the others, brightest first."""
    from scipy.ndimage import maximum_filter, median_filter
    v, var_w = window.crop(value).copy(), window.crop(var)
    clip, use = window.crop(clipped), window.crop(usable)
    v[clip] = max(v.max(), 1.0)
    v[~use & ~clip] = 0.0
    sig = np.sqrt(np.where(use, var_w, np.inf))
    ring = np.ones((5, 5), bool)
    ring[1:4, 1:4] = False
    snr = np.where(clip, np.inf, (v - median_filter(v, footprint=ring, mode="constant")) / sig)
    peak = (v == maximum_filter(v, 5, mode="constant")) & (snr >= PEAK_SNR) & (v > 1e-7 * v.max()) & ~clip
    ys, xs = np.nonzero(peak)
    order = np.argsort(-v[ys, xs])[:MAX_PEAKS]
    ys, xs = ys[order], xs[order]
    blobs, count = _clipped_regions(clip)
    if ys.size + len(blobs) < 3:
        raise FitError(f"no diffraction orders found: {ys.size + len(blobs)} peak(s) above {PEAK_SNR:g} σ in the "
                       f"{window.size}-px window: expected a laser spot with its orders (longer exposure?)")
    x, y, sigma = _centroids(v, var_w, ~use, ys, xs, CENTROID_RADIUS_PX)
    h = window.half
    xy = np.concatenate([blobs, np.stack([x, y], axis=1)]) - h
    blob_sigma = np.maximum(0.5, np.sqrt(count / math.pi) / 2)  # a quarter of the region's diameter
    return Peaks(xy, np.concatenate([blob_sigma, sigma]), np.concatenate([np.full(len(blobs), np.inf), snr[ys, xs]]),
                 np.arange(len(xy)) < len(blobs))


def _reduce(a: np.ndarray, b: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Lagrange–Gauss reduction: the shortest basis of the lattice spanned by a and b."""
    for _ in range(100):
        if b @ b < a @ a:
            a, b = b, a
        mu = round(float(a @ b) / float(a @ a))
        if mu == 0:
            break
        b = b - mu * a
    return a, b


def _supported(vectors: np.ndarray) -> np.ndarray:
    """Which peak vectors v have a peak at −v too (within 10 % of |v|, at least 1 px)."""
    tol = np.maximum(1.0, 0.1 * np.hypot(*vectors.T))
    d = np.hypot(*(vectors[:, None, :] + vectors[None, :, :]).transpose(2, 0, 1))
    return np.any(d < tol[:, None], axis=1)


def visible_basis(peaks: Peaks) -> np.ndarray:
    """[2, 2] columns a, b (px): the reduced basis of the orders' lattice (module doc, step 2), from the
    brightest peak (a saturated region's centroid where there is one) to the others."""
    v = peaks.xy[1:] - peaks.xy[0]
    ok = _supported(v) & (np.hypot(*v.T) >= MIN_SPACING_PX)
    cand = v[ok][np.argsort(np.hypot(*v[ok].T))]
    saturated = f" ({int(peaks.clipped.sum())} of them saturated)" if peaks.clipped.any() else ""
    if cand.shape[0] == 0:
        raise FitError("no diffraction orders found: no pair of peaks symmetric about the brightest: expected a laser "
                       "spot through a periodic display")
    for i, a in enumerate(cand[:BASIS_TRIES]):
        for b in cand[i + 1:]:
            if abs(a[0] * b[1] - a[1] * b[0]) > 0.25 * np.hypot(*a) * np.hypot(*b):
                basis = np.stack(_reduce(a.copy(), b.copy()), axis=1)
                if _on_lattice(v[:50], basis).mean() >= 0.6:
                    return basis
    raise FitError(f"no lattice of diffraction orders found: the orders{saturated} lie on one line "
                   "only or off any lattice: expected orders in two directions (a longer exposure shows the weak "
                   "ones, a shorter one the saturated)")


def _on_lattice(v: np.ndarray, basis: np.ndarray) -> np.ndarray:
    q = np.linalg.solve(basis, v.T)
    resid = np.hypot(*(v.T - basis @ np.round(q)))
    return resid < ASSIGN_TOLERANCE * min(np.hypot(*basis[:, 0]), np.hypot(*basis[:, 1]))


UNIMODULAR = [np.array(u).reshape(2, 2) for u in itertools.product((-1, 0, 1), repeat=4)
              if round(abs(np.linalg.det(np.array(u).reshape(2, 2)))) == 1]


def cell_basis(visible: np.ndarray, index_basis: np.ndarray) -> np.ndarray | None:
    """E [2, 2] (columns e_1, e_2, px per order) of a family whose visible orders are index_basis · Z²
    (module doc, step 3); None when no relabelling gives a right-handed cell within the rotation and skew
    limits."""
    best, key = None, None
    for u in UNIMODULAR:
        e = visible @ np.linalg.inv(index_basis @ u)
        if np.linalg.det(e) <= 0:
            continue
        rot = math.degrees(math.atan2(e[1, 0], e[0, 0]))
        skew = math.degrees(math.atan2(-e[0, 1], e[1, 1])) - rot
        if abs(rot) <= MAX_ROTATION_DEG and abs(skew) <= MAX_SKEW_DEG and (key is None or (abs(rot), abs(skew)) < key):
            best, key = e, (abs(rot), abs(skew))
    return best


@dataclass(frozen=True)
class Lattice:
    """The fitted lattice (window px): origin u_0, e_1, e_2, their covariances (x and y coordinates
    separately: cov_x of (x_0, e_1x, e_2x), cov_y of (y_0, e_1y, e_2y)), the peaks used with their cell
    orders and position noise, the scatter s beyond the noise and the RMS residual (px), the family's
    visible index basis."""
    origin: np.ndarray
    e1: np.ndarray
    e2: np.ndarray
    cov_x: np.ndarray
    cov_y: np.ndarray
    index: np.ndarray
    xy: np.ndarray
    sigma: np.ndarray
    floor_px: float
    rms_px: float
    index_basis: np.ndarray

    @property
    def spacing_px(self) -> float:
        return float(min(np.hypot(*self.e1), np.hypot(*self.e2)))

    def points(self, orders: np.ndarray) -> np.ndarray:
        """Window positions [N, 2] of cell orders [N, 2] (m, n)."""
        return self.origin[None, :] + orders[:, :1] * self.e1[None, :] + orders[:, 1:] * self.e2[None, :]

    def length(self, k: int) -> tuple[float, float]:
        """|e_k| and its σ (px): var = (e_x² var e_x + e_y² var e_y) / |e|²."""
        e = (self.e1, self.e2)[k]
        n = float(np.hypot(*e))
        var = (e[0] ** 2 * self.cov_x[k + 1, k + 1] + e[1] ** 2 * self.cov_y[k + 1, k + 1]) / n ** 2
        return n, math.sqrt(var)

    def angle_deg(self, k: int) -> tuple[float, float]:
        """The direction of e_1 (k = 0) or of e_2 turned back by 90° (k = 1) from the x axis towards +y, ± σ."""
        e = (self.e1, self.e2)[k]
        ex, ey = (e[0], e[1]) if k == 0 else (e[1], -e[0])
        n2 = ex * ex + ey * ey
        var = (ey ** 2 * self.cov_x[k + 1, k + 1] + ex ** 2 * self.cov_y[k + 1, k + 1]) / n2 ** 2 if k == 0 else \
            (ey ** 2 * self.cov_y[2, 2] + ex ** 2 * self.cov_x[2, 2]) / n2 ** 2
        return math.degrees(math.atan2(ey, ex)), math.degrees(math.sqrt(var))


def assign(peaks: Peaks, origin: np.ndarray, e: np.ndarray, index_basis: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(peak numbers, cell orders [N, 2]) of the peaks within ASSIGN_TOLERANCE of a visible order."""
    v = peaks.xy - origin
    q = np.round(np.linalg.solve(e, v.T)).T
    resid = np.hypot(*(v - q @ e.T).T)
    vis = np.linalg.solve(index_basis, q.T).T
    near = resid < ASSIGN_TOLERANCE * min(np.hypot(*e[:, 0]), np.hypot(*e[:, 1]))
    ok = near & np.all(np.abs(vis - np.round(vis)) < 1e-6, 1)
    keep = np.nonzero(ok)[0]
    _, first = np.unique(q[keep], axis=0, return_index=True)  # one peak per order: the brightest
    keep = keep[np.sort(first)]
    return keep, q[keep].astype(int)


def _floor(r2: np.ndarray, s2: np.ndarray, dof: int, robust: bool = False) -> float:
    """The scatter f² ≥ 0 with Σ r² / (s² + f²) = dof, or (robust) with median r² / (s² + f²) = ln 2 (the
    median of χ²₂ / 2, r² being the mean of the x and y residuals' squares: a few peaks far off the lattice, a
    wing's maximum beside a saturated order, do not set it); bisection, 0 when the noise explains the residuals."""
    ratio = (lambda f: float(np.median(r2 / (s2 + f))) - math.log(2)) if robust else \
        (lambda f: float(np.sum(r2 / (s2 + f))) - dof)
    if dof <= 0 or ratio(0.0) <= 0:
        return 0.0
    lo, hi = 0.0, float(np.max(r2)) + 1e-12
    for _ in range(80):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if ratio(mid) > 0 else (lo, mid)
    return 0.5 * (lo + hi)


def solve_lattice(xy: np.ndarray, sigma: np.ndarray, index: np.ndarray, index_basis: np.ndarray) -> Lattice:
    """The weighted least squares of module doc step 4 on peaks xy [N, 2] (position noise σ [N]) at cell
    orders index [N, 2]; peaks beyond 5 σ of the fit are left out (the first pass's σ with the robust scatter)."""
    s2 = sigma ** 2 + 1e-6
    a = np.column_stack([np.ones(len(xy)), index])
    use = np.ones(len(xy), bool)
    for i in range(4):
        sw = np.sqrt(s2[use, None])
        cx = np.linalg.lstsq(a[use] / sw, xy[use, 0] / sw[:, 0], rcond=None)[0]
        cy = np.linalg.lstsq(a[use] / sw, xy[use, 1] / sw[:, 0], rcond=None)[0]
        r2 = ((xy[:, 0] - a @ cx) ** 2 + (xy[:, 1] - a @ cy) ** 2) / 2
        f2 = _floor(r2[use], s2[use], int(use.sum()) - 3, robust=i == 0)
        use = r2 < 25 * (s2 + f2)
    cov = np.linalg.pinv(a[use].T @ (a[use] / (s2[use, None] + f2)))
    return Lattice(np.array([cx[0], cy[0]]), np.array([cx[1], cy[1]]), np.array([cx[2], cy[2]]), cov, cov,
                   index[use], xy[use], sigma[use], math.sqrt(f2), float(np.sqrt(np.mean(2 * r2[use]))), index_basis)


def light_centre(value: np.ndarray, usable: np.ndarray, window: Window) -> np.ndarray:
    """The window's centroid of light (window px): the zeroth order's place, since the PSF of a real mask at
    d = 0 is centrosymmetric (the brightest peak can be a first order: the T-OLED's are 0.8–0.95 of it)."""
    v = np.where(window.crop(usable), window.crop(value), 0.0)
    g = np.arange(window.size) - window.half
    total = v.sum()
    return np.array([np.sum(v.sum(axis=0) * g), np.sum(v.sum(axis=1) * g)]) / total


def fit_lattice(peaks: Peaks, e0: np.ndarray, index_basis: np.ndarray,
                centre: np.ndarray | None = None) -> tuple[Lattice, np.ndarray]:
    """(the lattice, the peaks' numbers used): solve_lattice three times on the unsaturated peaks, the orders
    assigned again with the previous pass's lattice (the far orders need the near ones' spacing); the zeroth
    order is the visible order nearest `centre` (light_centre; None: the brightest peak)."""
    origin, e = peaks.xy[0].copy(), e0
    if centre is not None:
        shift = index_basis @ np.round(np.linalg.solve(e0 @ index_basis, centre - origin))
        origin = origin + e0 @ shift
    for _ in range(3):
        keep, q = assign(peaks, origin, e, index_basis)
        free = ~peaks.clipped[keep]
        keep, q = keep[free], q[free]
        _check_spread(q, int(peaks.clipped.sum()))
        lat = solve_lattice(peaks.xy[keep], peaks.sigma[keep], q, index_basis)
        origin, e = lat.origin, np.stack([lat.e1, lat.e2], axis=1)
    return lat, keep


def _check_spread(q: np.ndarray, clipped: int) -> None:
    """Refuse unsaturated peaks that cannot fix a lattice: fewer than 4, or their orders on one line."""
    saturated = f" ({clipped} saturated region(s) left out)" if clipped else ""
    if len(q) < 4:
        raise FitError(f"no lattice of diffraction orders found: only {len(q)} unsaturated peaks on the "
                       f"lattice{saturated}: expected at least 4 (a shorter exposure shows the saturated orders)")
    if np.linalg.matrix_rank(np.column_stack([np.ones(len(q)), q])) < 3:
        d = q[np.argmax(np.hypot(*(q - q[0]).T))] - q[0]
        raise FitError(f"no lattice of diffraction orders found: the {len(q)} unsaturated orders lie on one line "
                       f"(along order ({int(d[0])}, {int(d[1])})){saturated}, so the spacing across it is not "
                       "measured: expected unsaturated orders in two directions (a shorter exposure for the "
                       "saturated ones, a longer one for the weak ones)")


def centroid_bias(model: np.ndarray, lattice: Lattice, e_model: np.ndarray, origin: np.ndarray) -> np.ndarray:
    """[N, 2] what the centroids of module doc step 1 find minus where the orders are, on a noise-free model
    image [S, S] whose orders lie at origin + E_model (m, n): at the pixels of the lattice's peaks."""
    h = model.shape[0] // 2
    ys, xs = np.rint(lattice.xy[:, 1]).astype(int) + h, np.rint(lattice.xy[:, 0]).astype(int) + h
    x, y, _ = _centroids(model, np.ones_like(model), np.zeros(model.shape, bool), ys, xs, CENTROID_RADIUS_PX)
    truth = origin[None, :] + lattice.index @ e_model.T
    return np.stack([x - h, y - h], axis=1) - truth
