"""Augmentation that respects the panel (issue 47, item 2).

A flip or transpose of a capture and its ground truth is the capture of the transformed scene only where the
panel's kernel is unchanged by it: a transposed T-OLED capture shows its diffraction vertically, which no capture
through that panel does. So:

- dataset pairs (restore.data.PairDataset): only the transforms (restore.data.dihedral's modes) under which the
  display's kernel is symmetric, per channel max |k − T(k)| / max k < SYMMETRY_TOLERANCE (udc_render.description.
  symmetric_modes), on the kernels of DeP (exact kernel) at the packed pitch in a SYMMETRY_KERNEL_PX window
  (udc_render.description.make.display_kernels) of the display the captures record (capture.json) for the rig
  they were made with (synth.json), at d = 0: the layout's and the lens's symmetry (at d > 0 the field phases of a
  mirror-symmetric layout map onto one another under the same mirror, psf.plan). Without a display record the
  kernel is unknown: the identity only. The modes and why are in train_summary.json ("augment").
- online (restore.online): every transform, applied to the clean crop before it is degraded (the panel's kernel
  then blurs the transformed scene, as a capture of it would): OnlineBatches.record says so.
"""
from __future__ import annotations

import json

from restore.data import ALL_MODES, DataError, PairDataset, list_pairs
from udc_render.description import symmetric_modes

# A transform is allowed where max |k − T(k)| / max k is below this in every channel. Measured at the default rig
# (1.55 µm pixels, SYMMETRY_KERNEL_PX): the T-OLED's flips 2e-8, its transposes 0.69; the P-OLED's transposes and
# double flip ≤ 5e-8, its single flips 3.4e-5 (all 8 allowed, 30× below the tolerance). In the description's
# 129-px window: the T-OLED's transposes 0.79, the P-OLED's single flips 8.5e-5: the same modes.
SYMMETRY_TOLERANCE = 1e-3
# The window the symmetry is tested in (packed pixels, odd; ±16 sensor px): the core and the first two orders of the
# T-OLED (10 µm apart at 520 nm), cheaper to make at train time than the description's 129 px and as telling.
SYMMETRY_KERNEL_PX = 17
ONLINE_WHY = "online: every transform, applied to the clean crop before the degradation (restore.augment)"


def display_modes(display, rig, sensor: dict, frame_px, kernel_px: int = SYMMETRY_KERNEL_PX,
                  tolerance: float = SYMMETRY_TOLERANCE) -> tuple[tuple[int, ...], str]:
    """(the modes the display's kernel (module doc) is symmetric under, why) for a sensor record (capture.json's
    "sensor") on frame_px (width, height)."""
    from udc_render.description.make import display_kernels
    kernels, _, _ = display_kernels(display.with_distance(0.0), rig, sensor["camera"], float(sensor["pitch_um"]),
                                    frame_px, kernel_px)
    modes, worst = symmetric_modes(kernels, tolerance)
    return modes, (f"the transforms {display.name}'s kernel is symmetric under (max |k − T(k)| / max k < "
                   f"{tolerance:g}; per mode {', '.join(f'{w:.2g}' for w in worst)})")


def pair_modes(pair) -> tuple[tuple[int, ...], str]:
    """(modes, why) of the display a dataset pair was captured through (module doc)."""
    from restore.known import capture_display
    from udc_render.description.make import dataset_rig
    capture = json.loads((pair.folder / pair.display / "capture.json").read_text())
    if capture.get("display") is None:
        return (0,), f"the identity only: {pair.folder / pair.display / 'capture.json'} records no display"
    from restore.data import load_gt
    h, w = load_gt(pair.folder).shape[1:]
    return display_modes(capture_display(pair), dataset_rig(pair.folder), capture["sensor"], (w, h))


def pair_dataset(data_dir, settings) -> PairDataset:
    """The PairDataset restore.train trains on (settings: TrainSettings) with the transforms of pair_modes."""
    pairs = list_pairs(data_dir, "train", [settings.display])
    if not pairs:
        raise DataError("no pairs to train on: the split is empty")
    modes, why = pair_modes(pairs[0])
    return PairDataset(pairs, settings.crop_px, augment=True, seed=settings.seed,
                       crops_per_pair=settings.crops_per_pair, modes=modes, modes_why=why)


__all__ = ["ALL_MODES", "ONLINE_WHY", "SYMMETRY_KERNEL_PX", "SYMMETRY_TOLERANCE", "display_modes", "pair_dataset",
           "pair_modes"]
