"""The online degradation for anyone's training loop (BasicSR, plain PyTorch): clean images and a kernel bank
in, (degraded, clean, description) batches out, seeded and resumable (docs/guides/api.md).

    from restore.api import OnlineDegradation
    data = OnlineDegradation("clean_images/", "bank/", crop_px=64, batch=4, seed=0)
    for x, y, d in data:            # epoch after epoch (epochs=None), or `epochs` of them
        loss = (net(x) - y).abs().mean()

Each batch, on `device`:
    x  [B, 4, c/2, c/2] float32  the degraded crop as a restorer sees it: packed RGGB (R, Gr, Gb, B) in
                                 (DN − black) / (white − black)
    y  [B, 3, c, c] float32      the clean crop: camera RGB in units of the white level, × the panel's brightness
    d  {name: tensor}            the panel's description, collated (restore.conditioning.description_tensors;
                                 the fields: udc_render.description), of the bank's frame

The crops are restore.online's: crop k of epoch e draws its image, panel, transform, place and noise from the named
stream (seed, 'online crop', e, k), in the epoch's order (seed, 'online order', e); the clean crop is turned
before it is degraded (restore.augment: every transform is the capture of a transformed scene). The same seed,
epoch and batch give the same batch in any process. Resuming: state_dict() after the batches taken,
load_state_dict(state) on a new OnlineDegradation continues with the next one.

Clean images: a dataset folder (its train split's gt.exr), a folder of linear RGB .exr (restore.online.
clean_images), a folder of .png (8 or 16 bits, sRGB: decoded to linear with the sRGB transfer function and taken as
the camera's RGB, 1.0 the white level: an approximation of a capture's colour), or a list of linear RGB arrays
[3, H, W] (H, W even). Bank: a folder of `udc-render bank` or a udc_render.dataset.bank.Bank.
"""
from __future__ import annotations

from pathlib import Path

import imageio.v3 as iio
import numpy as np
import torch

from restore.conditioning import crop_description, description_tensors
from restore.data import DataError
from restore.degrade import Degrader
from restore.online import CleanImage, OnlineBatches, checked_image, clean_images
from udc_render.dataset.bank import Bank, read_bank
from udc_render.description import PanelDescription
from udc_render.description.make import describe_panel

__all__ = ["OnlineDegradation", "load_clean_images", "srgb_to_linear"]


def srgb_to_linear(v: np.ndarray) -> np.ndarray:
    """The sRGB transfer function inverted (IEC 61966-2-1): v / 12.92 below 0.04045, else ((v + 0.055) / 1.055)^2.4."""
    v = np.asarray(v, np.float64)
    return np.where(v <= 0.04045, v / 12.92, ((v + 0.055) / 1.055) ** 2.4)


def _png(path: Path) -> np.ndarray:
    a = iio.imread(path)
    if a.ndim != 3 or a.shape[2] < 3 or a.dtype not in (np.uint8, np.uint16):
        raise DataError(f"{path}: shape {a.shape}, {a.dtype}: expected an 8- or 16-bit RGB(A) PNG")
    return np.moveaxis(srgb_to_linear(a[..., :3] / np.iinfo(a.dtype).max), -1, 0).astype(np.float32)


def load_clean_images(images) -> list[CleanImage]:
    """The clean images of `images` (module doc), each checked (finite, ≥ 0) and cut to whole RGGB cells."""
    if isinstance(images, (list, tuple)):
        return [checked_image(f"image {i}", np.asarray(a, np.float32)) for i, a in enumerate(images)]
    folder = Path(images)
    pngs = sorted(p for p in folder.rglob("*.png")) if folder.is_dir() else []
    if pngs and not any(folder.rglob("*.exr")):
        return [checked_image(str(p), _png(p)) for p in pngs]
    return clean_images(folder, "train")


class OnlineDegradation(torch.utils.data.IterableDataset):
    """(degraded, clean, description) batches of clean images through a kernel bank (module doc). epochs None:
    endless; workers: processes degrading beside the caller on the CPU (restore.online; 0: in this one)."""

    def __init__(self, images, bank, crop_px: int = 256, batch: int = 4, seed: int = 0, crops_per_image: int = 1,
                 device: str | torch.device = "cpu", workers: int = 0, epochs: int | None = None,
                 frame_px: tuple[int, int] | None = None):
        bank = bank if isinstance(bank, Bank) else read_bank(Path(bank))
        frame = frame_px or bank.settings.get("frame_px")
        if frame is None:
            raise DataError(f"--bank {bank.folder}: its bank.json names no frame_px: give frame_px (width, height), "
                            "the sensor frame its panels were made for")
        self.frame_px = (int(frame[0]), int(frame[1]))
        degrader = Degrader(bank.panels, torch.device(device), torch.float32)
        self.batches = OnlineBatches(load_clean_images(images), bank, degrader, crop_px, batch, seed,
                                     crops_per_image, workers)
        self.descriptions = [describe_panel(p, self.frame_px) for p in bank.panels]
        self.epochs, self.epoch, self.batch_index = epochs, 0, 0

    def __len__(self) -> int:
        """Batches per epoch."""
        return (self.batches.crops + self.batches.batch - 1) // self.batches.batch

    def state_dict(self) -> dict:
        """Where the iteration stands: the next batch is batch `batch` of epoch `epoch`."""
        return {"epoch": self.epoch, "batch": self.batch_index}

    def load_state_dict(self, state: dict) -> None:
        self.epoch, self.batch_index = int(state["epoch"]), int(state["batch"])

    def description(self, draw: dict) -> PanelDescription:
        """The description of a crop's draw: its panel's, with its own drawn sensor under capture draws (restore.
        conditioning.crop_description, what `udc-render train` gives a model that needs it)."""
        return crop_description(self.descriptions, self.batches.bank, draw)

    def __iter__(self):
        b, dev = self.batches.batch, self.batches.degrader.device
        while self.epochs is None or self.epoch < self.epochs:
            draws = self.batches.epoch_draws(self.epoch)
            rest = draws[self.batch_index * b:]
            for i, (x, y) in enumerate(self.batches.batches_of(rest)):
                chunk = rest[i * b:(i + 1) * b]
                self.batch_index += 1
                yield x, y, description_tensors([self.description(d) for d in chunk], dev)
            self.epoch, self.batch_index = self.epoch + 1, 0
