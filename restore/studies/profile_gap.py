"""How far two profiles' captures of the same items differ: the synthetic-to-real gap our data can hold.

The `paper` and `physical` datasets of `udc-render results` render the same items (same content, render
seeds and noise seeds), so their captures differ only by what the profiles change (udc_render.profiles).
Per display and item, on the packed RAW in [0, 1] of the white level:
- PSNR between the two captures (noise, optics and defects together);
- the same without the saturated hot pixels (≥ SATURATED in one capture, < 0.9 in the other);
- PSNR of 8 × 8 block means (BLOCK_PX), where the per-pixel noise has mostly averaged out: the
  deterministic difference of the optics;
- the ratio of channel means (R, Gr, Gb, B): the colour gap.

    python -m restore.studies.profile_gap out/results/dataset_physical out/results/dataset_paper [ITEMS]
"""
from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

from udc_render.metrics import psnr_db

SATURATED, BLOCK_PX = 0.98, 8


def block_means(x: np.ndarray, k: int = BLOCK_PX) -> np.ndarray:
    """[C, H, W] → [C, H // k, W // k] means of k × k blocks (the remainder cropped)."""
    c, h, w = x.shape[0], x.shape[1] // k * k, x.shape[2] // k * k
    return x[:, :h, :w].reshape(c, h // k, k, w // k, k).mean(axis=(2, 4))


def capture_gap(a: np.ndarray, b: np.ndarray) -> dict:
    """The gap between two packed captures [4, H, W] of the same item (module doc)."""
    a, b = np.asarray(a, np.float64), np.asarray(b, np.float64)
    hot = ((a >= SATURATED) & (b < 0.9)) | ((b >= SATURATED) & (a < 0.9))
    mse_cool = float(np.mean((a - b)[~hot] ** 2))
    return {"psnr_db": psnr_db(a, b), "psnr_db_without_hot": 10 * np.log10(1 / mse_cool), "hot_px": int(hot.sum()),
            "block_psnr_db": psnr_db(block_means(a), block_means(b)),
            "channel_ratio": (a.mean(axis=(1, 2)) / b.mean(axis=(1, 2))).tolist()}


def profile_gaps(data_a: Path, data_b: Path, displays=("toled", "poled"), items: int = 3) -> list[dict]:
    """capture_gap of the first `items` test items of each display, A against B."""
    from restore.data import list_pairs, load_pair
    rows = []
    for d in displays:
        b_pairs = {p.item: p for p in list_pairs(Path(data_b), "test", [d])}
        for p in list_pairs(Path(data_a), "test", [d])[:items]:
            rows.append({"display": d, "item": p.item,
                         **capture_gap(load_pair(p)[0], load_pair(b_pairs[p.item])[0])})
    return rows


def main(argv: list[str]) -> None:
    rows = profile_gaps(Path(argv[0]), Path(argv[1]), items=int(argv[2]) if len(argv) > 2 else 3)
    print("| display | item | PSNR (dB) | without hot pixels (dB) | hot pixels | 8×8 block PSNR (dB) | "
          "A/B channel means |")
    print("|---|---|---|---|---|---|---|")
    for r in rows:
        print(f"| {r['display']} | {r['item']} | {r['psnr_db']:.2f} | {r['psnr_db_without_hot']:.2f} | {r['hot_px']} | "
              f"{r['block_psnr_db']:.2f} | {' '.join(f'{v:.4f}' for v in r['channel_ratio'])} |")


if __name__ == "__main__":
    main(sys.argv[1:])
