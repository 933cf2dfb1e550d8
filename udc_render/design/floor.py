"""`design --upc-floor R`: hold UPC's statistic at R × the T-OLED's while the search lowers the rig's objective.

The rig's objectives J ('wiener', 'crop', with or without the far veil) become

    J · (1 + FLOOR_WEIGHT Σ_c max(0, log(R m_c^ref) − log m_c)),

m_c the mean ring minimum of the cell's MTF in UPC's sampling (upc.psf, mtf.mean_ring_minima) in the floor's
channels, m^ref the same of the preset T-OLED at the open area with its slit at the tile's edge (cells.toled_reference:
design.json's UPC reference), both on the search's D4 tiling of UPC's display. FLOOR_WEIGHT = 10: a cell 1 % below the
floor costs 10 % of J, more than the whole gain of the far-veil search over the T-OLED (4.5 % of J held out, 6.1 % on
the search's tiling; docs/figures/design/design_veil), so the swaps the search takes keep a floor once it holds (the
committed runs end at their floors or above on the search's tiling, none more than 0.06 % below); from below it
the hinge's gradient ranks the swaps that climb. The held-out tiling's ratio is design.json's `upc` (the issue's
target: green, 1.26 ×).

UPC's PSF is normalised after their crop, so a cell that throws light past it raises the statistic by 1 / share
(upc.kept_fraction); floor_uncropped holds m · share instead, the statistic of the PSF normalised before the crop,
which the crop cannot inflate.
"""
from __future__ import annotations

import torch

from udc_render.design import torch_psf as tp, upc
from udc_render.design.cells import resample_matrix, toled_reference
from udc_render.design.mtf import mean_ring_minima, ring_index
from udc_render.design.options import CHANNELS

__all__ = ["FLOOR_WEIGHT", "UpcFloor", "hinge_factor"]

FLOOR_WEIGHT = 10.0


def hinge_factor(ratios: torch.Tensor, bound: float, weight: float, ceiling: bool = False) -> torch.Tensor:
    """1 + weight Σ_c max(0, log bound − log ratio_c) (a floor), or max(0, log ratio_c − log bound) (a ceiling): the
    factor by which a bound on ratios to the T-OLED multiplies the objective (this floor, design.bands' ceiling)."""
    below = torch.log(torch.tensor(bound, dtype=ratios.dtype)) - torch.log(ratios)
    return 1 + weight * torch.relu(-below if ceiling else below).sum()


class UpcFloor:
    """The floor's factor 1 + FLOOR_WEIGHT · hinge (module doc) of a cell on a named tiling ('search', 'final')."""

    def __init__(self, ratio: float, channels: str, cell_px: int, cell_um: float, open_fraction: float,
                 seed: int, turned: bool, uncropped: bool = False, device: str = "cpu"):
        self.ratio, self.seed, self.turned, self.uncropped = ratio, seed, turned, uncropped
        self.index = [CHANNELS.index(c) for c in channels]
        self.rings = ring_index(upc.PSF_PX)
        self.weights = torch.tensor(resample_matrix(cell_px), device=device)
        self.reference = torch.tensor(toled_reference(cell_um, open_fraction), device=device)
        self._ref_minima: dict[str, torch.Tensor] = {}

    def transforms(self, which: str):
        return tp.tile_transforms(upc.TILES, self.seed, keys=("design", which)) if self.turned else None

    def minima(self, cell21: torch.Tensor, which: str) -> torch.Tensor:
        """[channels] UPC's mean ring minima of a 21 × 21 cell on the tiling (uncropped: times the share inside
        their crop, the statistic of the PSF normalised before the crop)."""
        p, kept = upc.psf_and_kept(cell21, self.transforms(which))
        m = mean_ring_minima(p[self.index], self.rings)
        return m * kept[self.index] if self.uncropped else m

    def ratios(self, cell: torch.Tensor, which: str) -> torch.Tensor:
        """[channels] the cell's mean ring minima over the T-OLED's, on the tiling."""
        if which not in self._ref_minima:
            with torch.no_grad():
                self._ref_minima[which] = self.minima(self.reference, which)
        w = self.weights.to(cell.dtype)
        return self.minima(w @ cell @ w.T, which) / self._ref_minima[which].to(cell.dtype)

    def factor(self, cell: torch.Tensor, which: str) -> torch.Tensor:
        """1 + FLOOR_WEIGHT Σ_c max(0, log R − log ratio_c) (hinge_factor)."""
        return hinge_factor(self.ratios(cell, which), self.ratio, FLOOR_WEIGHT)
