"""Procedural test charts for the virtual monitor, in linear drive levels [rows, cols] within [0, 1].

Each panel pixel shows one value (the monitor is a pixel grid), computed at the pixel centre
(x, y) = (col + 0.5, row + 0.5), origin at the panel's top-left corner, y down.

- slanted_edge: ISO 12233 style, a near-vertical edge through the centre tilted by `angle_deg`
  (default 5°), levels 0.2 | 0.8 (4:1 contrast); the edge pixels take the clipped signed distance
  clip(0.5 + d, 0, 1) as coverage (exact for |d| ≤ (1 − tan θ)/2, within tan θ / 8 otherwise).
- sine_x / sine_y: 0.5 + 0.5 sin(2π n x / cols) (or y / rows), n whole cycles across the panel.
- siemens: sinusoidal Siemens star, 0.5 + 0.5 sin(n φ) with n spokes, radius 0.45 × rows; 0.5 outside.
- dead_leaves: occluding discs (Lee, Mumford & Huang 2001; Cao et al. 2010) with radii drawn from
  p(r) ∝ r⁻³ on [r_min, r_max] and uniform grey levels, painted front to back until every pixel is
  covered; scale-invariant texture for texture-MTF studies. Seeded.
- dead_leaves_colour: the same discs, each painted with one colour drawn from a palette (e.g. a
  photograph's pixels), so the image has the dead leaves' occlusion statistics and a photograph's
  colours and brightness: the synthetic training images of Achddou, Gousseau & Ladjal (2021,
  "Synthetic images as a regularity prior for image restoration neural networks"). [3, rows, cols].
"""
from __future__ import annotations

import math

import numpy as np

DEAD_LEAVES_R_MIN_PX = 4.0
DEAD_LEAVES_R_MAX_FRACTION = 0.25  # of the panel height


def _centres(cols: int, rows: int):
    return np.arange(cols) + 0.5, np.arange(rows) + 0.5


def slanted_edge(cols: int, rows: int, angle_deg: float = 5.0, low: float = 0.2, high: float = 0.8) -> np.ndarray:
    """Dark left, bright right; the edge x = cx + (y − cy) tan θ (θ clockwise from vertical)."""
    x, y = _centres(cols, rows)
    t = math.tan(math.radians(angle_deg))
    d = (x[None, :] - cols / 2 - (y[:, None] - rows / 2) * t) / math.sqrt(1 + t * t)  # px, + on the bright side
    return low + (high - low) * np.clip(0.5 + d, 0.0, 1.0)


def sine(cols: int, rows: int, cycles: float, axis: str = "x") -> np.ndarray:
    x, y = _centres(cols, rows)
    if axis == "x":
        return np.broadcast_to(0.5 + 0.5 * np.sin(2 * np.pi * cycles * x / cols), (rows, cols)).copy()
    return np.broadcast_to((0.5 + 0.5 * np.sin(2 * np.pi * cycles * y / rows))[:, None], (rows, cols)).copy()


def siemens(cols: int, rows: int, spokes: int = 72) -> np.ndarray:
    x, y = _centres(cols, rows)
    dx, dy = x[None, :] - cols / 2, y[:, None] - rows / 2
    star = 0.5 + 0.5 * np.sin(spokes * np.arctan2(dy, dx))
    return np.where(np.hypot(dx, dy) <= 0.45 * rows, star, 0.5)


DEAD_LEAVES_BATCH = 4096  # discs drawn at a time (u, x, y, value: the draws' order fixes every image)
VECTOR_PAIRS = 1 << 23  # discs × uncovered pixels tested at once when few pixels are left (the late batches)
CULL_BLOCK_PX = 16  # the blocks of the uncovered-pixel map that decide which discs can still fill a pixel


def dead_leaves(cols: int, rows: int, seed: int = 0, r_min_px: float = DEAD_LEAVES_R_MIN_PX,
                r_max_px: float | None = None) -> np.ndarray:
    """Front-to-back occluding discs: each new disc fills only the pixels not yet covered, so a pixel takes the
    value of the first disc whose circle holds its centre. While many pixels are uncovered, a batch's discs one by
    one, skipping those whose box meets no block with an uncovered pixel; when few are left (the last pixels take
    most of the discs: 93 % of them at 3840 × 2160), every disc of a batch against every uncovered pixel at once."""
    rng = np.random.default_rng(seed)
    r_max = r_max_px or DEAD_LEAVES_R_MAX_FRACTION * rows
    img = np.zeros((rows, cols))
    covered = np.zeros((rows, cols), bool)
    left, pending = rows * cols, None
    while left:
        u = rng.random(DEAD_LEAVES_BATCH)  # inverse CDF of p(r) ∝ r⁻³: r⁻² uniform between r_max⁻² and r_min⁻²
        radii = (r_min_px ** -2 + u * (r_max ** -2 - r_min_px ** -2)) ** -0.5
        cx, cy, value = (rng.random(DEAD_LEAVES_BATCH) * cols, rng.random(DEAD_LEAVES_BATCH) * rows,
                         rng.random(DEAD_LEAVES_BATCH))
        boxes = _boxes(radii, cx, cy, rows, cols)
        if pending is None and left * DEAD_LEAVES_BATCH <= VECTOR_PAIRS:
            pending = np.nonzero(~covered)
        if pending is None:
            left -= _fill_discs(img, covered, radii, cx, cy, value, boxes, left)
        else:
            pending = _fill_pixels(img, pending, radii, cx, cy, value, boxes)
            left = pending[0].size
    return img


def _boxes(radii, cx, cy, rows: int, cols: int) -> np.ndarray:
    """[n, 4] each disc's pixel box (r0, r1, c0, c1): the rows and columns whose centres it may hold."""
    return np.stack([np.maximum((cy - radii).astype(np.int64), 0), np.minimum((cy + radii).astype(np.int64) + 1, rows),
                     np.maximum((cx - radii).astype(np.int64), 0), np.minimum((cx + radii).astype(np.int64) + 1, cols)],
                    axis=1)


def _open_discs(covered: np.ndarray, boxes: np.ndarray) -> np.ndarray:
    """The discs whose box meets a CULL_BLOCK_PX block holding an uncovered pixel (a summed-area table of them)."""
    b = CULL_BLOCK_PX
    h, w = covered.shape
    padded = np.ones((-(-h // b) * b, -(-w // b) * b), bool)
    padded[:h, :w] = covered
    open_blocks = ~padded.reshape(padded.shape[0] // b, b, padded.shape[1] // b, b).all(axis=(1, 3))
    table = np.zeros((open_blocks.shape[0] + 1, open_blocks.shape[1] + 1), np.int64)
    np.cumsum(np.cumsum(open_blocks, axis=0), axis=1, out=table[1:, 1:])
    r0, r1, c0, c1 = boxes[:, 0] // b, (boxes[:, 1] - 1) // b + 1, boxes[:, 2] // b, (boxes[:, 3] - 1) // b + 1
    return np.flatnonzero(table[r1, c1] - table[r0, c1] - table[r1, c0] + table[r0, c0] > 0)


def _fill_discs(img, covered, radii, cx, cy, value, boxes, left: int) -> int:
    """The batch's discs in order on the pixels they are first to cover; returns how many were filled."""
    filled = 0
    for i in _open_discs(covered, boxes):
        a, b, c, d, x0, y0, r = *boxes[i], cx[i], cy[i], radii[i]
        yy = np.arange(a, b)[:, None] + 0.5 - y0
        xx = np.arange(c, d)[None, :] + 0.5 - x0
        new = (xx * xx + yy * yy <= r * r) & ~covered[a:b, c:d]
        n = int(new.sum())
        if n:
            img[a:b, c:d][new] = value[i]
            covered[a:b, c:d] |= new
            filled += n
            if filled == left:
                break
    return filled


def _fill_pixels(img, pending: tuple, radii, cx, cy, value, boxes) -> tuple:
    """Every pending pixel (rows, cols) takes the first disc of the batch that holds its centre (the same test as
    _fill_discs); returns the pixels still uncovered."""
    rows, cols = pending
    inside = ((boxes[:, 0, None] <= rows) & (rows < boxes[:, 1, None]) & (boxes[:, 2, None] <= cols)
              & (cols < boxes[:, 3, None]))
    xx = cols[None, :] + 0.5 - cx[:, None]
    yy = rows[None, :] + 0.5 - cy[:, None]
    inside &= xx * xx + yy * yy <= (radii * radii)[:, None]
    hit = inside.any(axis=0)
    img[rows[hit], cols[hit]] = value[inside.argmax(axis=0)[hit]]
    return rows[~hit], cols[~hit]


def dead_leaves_colour(cols: int, rows: int, seed: int, palette: np.ndarray) -> np.ndarray:
    """[3, rows, cols]: dead_leaves(cols, rows, seed)'s discs, disc of grey level v painted with
    palette[⌊v · N⌋] (palette [N, 3] linear drive levels in [0, 1]): a uniform draw from the palette per disc."""
    palette = np.asarray(palette, dtype=np.float64)
    if palette.ndim != 2 or palette.shape[1] != 3 or len(palette) < 1:
        raise ValueError(f"palette: shape {palette.shape}: expected [N, 3] colours, N ≥ 1")
    index = np.minimum((dead_leaves(cols, rows, seed) * len(palette)).astype(np.int64), len(palette) - 1)
    return np.moveaxis(palette[index], -1, 0)
