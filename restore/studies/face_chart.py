"""Face chart for the downstream face-detection experiment, from images bundled with scikit-image.

`face_chart` lays out the first 100 images of `skimage.data.lfw_subset()` (25 × 25 px grey,
tightly cropped faces from Labeled Faces in the Wild) scaled to `face_px` (log-uniform: as many small
faces as large ones per octave), one per cell of a 200 px grid, each at a contrast c drawn uniformly from
`contrast` (the face's deviation from its own mean scaled by c), on a smooth random colour texture or
plain grey. The defaults (STUDY_FACE_PX, STUDY_CONTRAST) make a chart on which MTCNN misses faces even
clean, as the paper's figure (60 % clean recall): through the rig at 2048 × 1024 (glass, noise-free
ground truth) MTCNN finds 28 of 45 (62 %; behind the T-OLED 1, the P-OLED 0: the paper's 8 % and 0 %);
(60, 160) px at full contrast is the easy chart (45 of 45). The ground-truth box of a face tile of
side s at (x, y) follows MTCNN's box convention: (x + 0.06 s, y, x + 0.82 s, y + 0.96 s), the
median MTCNN box relative to the tile measured over 135 faces on three charts (the detector cuts
the tiles' left and right margins). Against these boxes MTCNN's mean IoU on a clean chart is
about 0.85; against the bare tiles it is 0.48–0.78.
"""
from __future__ import annotations

import numpy as np

STUDY_FACE_PX = (12, 140)            # the study's faces: from below MTCNN's smallest (about 20 px) up
STUDY_CONTRAST = (0.05, 1.0)         # the study's contrasts
FACE_BOX = (0.06, 0.0, 0.82, 0.96)   # ground-truth box as fractions of the tile side (x1, y1, x2, y2)
CELL_PX = 200                        # grid cell; faces are at most CELL_PX − GAP_PX wide
GAP_PX = 24                          # least gap between two tiles


def face_chart(width_px: int = 1920, height_px: int = 1080, seed: int = 0, face_px=STUDY_FACE_PX,
               background: str = "texture", contrast=STUDY_CONTRAST) -> tuple[np.ndarray, np.ndarray]:
    """(image uint8 [H, W, 3], true boxes [N, 4] x1, y1, x2, y2 in pixels): N = ⌊W/200⌋ ⌊H/200⌋ faces.

    Sizes (log-uniform in `face_px`), contrasts (uniform in `contrast`), positions within their cells and
    the choice of faces depend only on `seed`. `background`: "texture" (0.5 plus Gaussian-smoothed noise per
    channel, σ 6 px, standard deviation 0.15) or "grey" (0.5).
    """
    from scipy.ndimage import gaussian_filter
    from skimage import data
    from skimage.transform import resize

    lo, hi = face_px
    if not 12 <= lo <= hi <= CELL_PX - GAP_PX:
        raise ValueError(f"face_px must satisfy 12 ≤ min ≤ max ≤ {CELL_PX - GAP_PX}, got {face_px}")
    c_lo, c_hi = contrast
    if not 0 < c_lo <= c_hi <= 1:
        raise ValueError(f"contrast must satisfy 0 < min ≤ max ≤ 1, got {contrast}")
    rows, cols = height_px // CELL_PX, width_px // CELL_PX
    if rows * cols == 0:
        raise ValueError(f"a face chart needs at least {CELL_PX} × {CELL_PX} px, got {width_px} × {height_px}")
    rng = np.random.default_rng(seed)
    if background == "texture":
        noise = gaussian_filter(rng.standard_normal((height_px, width_px, 3)), (6, 6, 0))
        img = 0.5 + 0.15 * noise / noise.std()
    elif background == "grey":
        img = np.full((height_px, width_px, 3), 0.5)
    else:
        raise ValueError(f"unknown background {background!r} (texture, grey)")
    faces = data.lfw_subset()[:100]
    picks = rng.choice(len(faces), rows * cols, replace=rows * cols > len(faces))
    y0, x0 = (height_px - rows * CELL_PX) // 2, (width_px - cols * CELL_PX) // 2
    boxes = []
    for k, (r, c) in enumerate(np.ndindex(rows, cols)):
        s = int(round(np.exp(rng.uniform(np.log(lo), np.log(hi)))))
        y = y0 + r * CELL_PX + GAP_PX // 2 + int(rng.integers(0, CELL_PX - GAP_PX - s + 1))
        x = x0 + c * CELL_PX + GAP_PX // 2 + int(rng.integers(0, CELL_PX - GAP_PX - s + 1))
        tile = resize(faces[picks[k]], (s, s), order=3)
        tile = tile.mean() + rng.uniform(c_lo, c_hi) * (tile - tile.mean())
        img[y:y + s, x:x + s] = tile[:, :, None]
        boxes.append([x + FACE_BOX[0] * s, y + FACE_BOX[1] * s, x + FACE_BOX[2] * s, y + FACE_BOX[3] * s])
    return (np.clip(img, 0, 1) * 255 + 0.5).astype(np.uint8), np.asarray(boxes, dtype=np.float64)
