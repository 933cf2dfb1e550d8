"""The settings of one `udc-render design` run (udc_render.design.optimise), checked when made: each refusal one
line naming the option, its value and what is allowed. A checkpoint keeps them; a resumed run must match."""
from __future__ import annotations

from dataclasses import dataclass

from udc_render.design import metrics, torch_psf as tp, upc
from udc_render.design.cells import read_cell
from udc_render.design.options import (
    ARRANGEMENT_TILES,
    CHANNELS,
    CONTRAST_DEFAULTS,
    CROP_PX,
    DEFAULT_FEATURE_UM,
    INITS,
    LITHOGRAPHY_UM,
    OBJECTIVES,
    OPTICS,
    RIG_PIXEL_UM,
    SYMMETRIES,
    TILINGS,
)
from udc_render.design.symmetry import check_symmetric

__all__ = ["DesignConfig"]


def _check_channels(option: str, channels: str) -> None:
    if not (channels and set(channels) <= set(CHANNELS) and len(set(channels)) == len(channels)):
        raise tp.DesignError(f"{option} {channels}: expected some of {CHANNELS}, each once")


@dataclass(frozen=True)
class DesignConfig:
    """Every setting of one design run (the checkpoint keeps it: a resumed run must match)."""
    cell_um: float = 168.0
    feature_um: float = DEFAULT_FEATURE_UM
    open_fraction: float = 0.20
    tiling: str = "turned"
    objective: str = "wiener"
    steps: int = 150
    candidates: int = 40
    seed: int = 0
    pupil_samples: int = 512
    kernel_px: int = 127
    scatters: int = 20
    crop_px: int = CROP_PX
    contrast: float | None = None  # None: the objective's (options.CONTRAST_DEFAULTS)
    init: str = "scatter"
    optics: str = "rig"
    channels: str = CHANNELS
    far_veil: bool = False
    upc_floor: float | None = None
    floor_channels: str = "G"
    floor_uncropped: bool = False
    banding_ceiling: float | None = None
    kicks: int = 0
    kick_swaps: int = 4
    search_tilings: int = 1
    channel_step_nm: float = 0.0  # > 0: the objective's channels summed over the camera's band (optimise module doc)
    reference: bool = False  # the scorer of a reference cell (design.held_out's T-OLEDs), not a design: no LTPS limit
    mean_level: float | None = None  # μ, a fraction of the glass capture's full well; None: metrics.MEAN_LEVEL
    symmetry: str = "none"  # 'c2': a point-symmetric cell, no dipole (udc_render.design.symmetry)
    pixel_um: float = RIG_PIXEL_UM  # the objective's sensor pitch (its kernels' pixels), µm
    packed: bool = False  # the objective on the packed planes (2 × pixel_um) that DeP restores (torch_psf.packed)
    arrangement: int = ARRANGEMENT_TILES  # with tiling 'arranged': the K of its K × K pattern of D4 tiles

    def __post_init__(self):
        if self.contrast is None:
            object.__setattr__(self, "contrast", CONTRAST_DEFAULTS.get(self.objective, metrics.RMS_CONTRAST))
        if self.mean_level is None:
            object.__setattr__(self, "mean_level", metrics.MEAN_LEVEL)
        if not 0 < self.open_fraction < 1:
            raise tp.DesignError(f"--open-area {self.open_fraction}: expected a fraction in (0, 1)")
        if not (self.feature_um >= LITHOGRAPHY_UM or self.reference and self.feature_um > 0):
            raise tp.DesignError(f"--feature-um {self.feature_um}: below the {LITHOGRAPHY_UM} µm that backplane "
                                 "lithography patterns (LTPS); expected ≥ 1.5")
        n = self.cell_um / self.feature_um
        if not (self.cell_um > 0 and abs(n - round(n)) < 1e-9 and round(n) >= 3):
            raise tp.DesignError(f"--cell-um {self.cell_um}: the minimum feature size {self.feature_um} µm cannot "
                                 f"tile it; expected a multiple (≥ 3 ×) of the feature size")
        if round(self.open_fraction * self.cell_px ** 2) < 1:
            raise tp.DesignError(f"--open-area {self.open_fraction}: less than one {self.feature_um} µm square of "
                                 f"the {self.cell_px} × {self.cell_px} cell")
        if not self.pixel_um > 0:
            raise tp.DesignError(f"--pixel-um {self.pixel_um}: expected a sensor pitch > 0 µm")
        if self.packed and (self.optics != "rig" or self.objective not in ("wiener", "crop")):
            raise tp.DesignError(f"--packed: takes --optics rig with --objective wiener or crop (DeP's kernel), got "
                                 f"--optics {self.optics} --objective {self.objective}")
        if not (isinstance(self.crop_px, int) and self.crop_px >= 2):
            raise tp.DesignError(f"--crop-px {self.crop_px}: expected an integer ≥ 2")
        if not self.contrast > 0:
            raise tp.DesignError(f"--contrast {self.contrast}: expected an RMS contrast > 0")
        if not 0 < self.mean_level <= 1:
            raise tp.DesignError(f"--mean-level {self.mean_level}: expected a fraction of the full well in (0, 1]")
        for key, allowed in (("tiling", TILINGS), ("objective", OBJECTIVES), ("optics", OPTICS)):
            if getattr(self, key) not in allowed:
                raise tp.DesignError(f"--{key} {getattr(self, key)}: expected one of {', '.join(allowed)}")
        _check_channels("--channels", self.channels)
        self._check_symmetry(None if self.init in INITS else read_cell(self.init, self.cell_px, self.open_squares))
        if self.optics == "upc":
            self._check_upc()
        if self.search_tilings > 1 and self.tiling != "turned":
            raise tp.DesignError(f"--search-tilings {self.search_tilings}: takes --tiling turned (a repeated tiling "
                                 "has one draw)")
        self._check_floor()
        self._check_ceiling()
        self._check_arranged()
        if not (self.channel_step_nm == 0 or self.channel_step_nm >= 1 and self.optics == "rig"):
            raise tp.DesignError(f"--channel-step {self.channel_step_nm}: expected 0 (the rig's 640 / 520 / 450 nm) "
                                 f"or a step ≥ 1 nm (the engine's own is λ / S ≈ 1.6 nm), with --optics rig; got "
                                 f"--optics {self.optics}")
        if self.far_veil and self.objective not in ("wiener", "crop"):
            raise tp.DesignError(f"--far-veil: takes --objective wiener or crop (the light past the kernel's window), "
                                 f"got {self.objective}")
        for key in ("steps", "candidates", "scatters", "kick_swaps", "search_tilings"):
            if not (isinstance(getattr(self, key), int) and getattr(self, key) >= 1):
                raise tp.DesignError(f"--{key.replace('_', '-')} {getattr(self, key)}: expected an integer ≥ 1")
        if not (isinstance(self.kicks, int) and self.kicks >= 0):
            raise tp.DesignError(f"--kicks {self.kicks}: expected an integer ≥ 0")
        most = min(self.open_squares, self.cell_px ** 2 - self.open_squares) // (2 if self.symmetry == "c2" else 1)
        if self.kicks and self.kick_swaps > most:
            unit = "square pairs" if self.symmetry == "c2" else "squares"
            raise tp.DesignError(f"--kick-swaps {self.kick_swaps}: the cell has {most} {unit} to swap; expected "
                                 f"1 … {most}")

    def _check_symmetry(self, start) -> None:
        """The symmetry known and the start able to keep it (start: the --init cell PNG's cell, or None)."""
        if self.symmetry not in SYMMETRIES:
            raise tp.DesignError(f"--symmetry {self.symmetry}: expected one of {', '.join(SYMMETRIES)}")
        if self.symmetry == "none":
            return
        if self.init == "toled":
            raise tp.DesignError("--symmetry c2: --init toled is not point-symmetric (its slit at the tile's edge); "
                                 "start from scatter or a point-symmetric cell.png")
        if self.cell_px % 2 == 0 and self.open_squares % 2:
            raise tp.DesignError(f"--symmetry c2: {self.open_squares} open squares (--open-area "
                                 f"{self.open_fraction}) are odd, and the even {self.cell_px}² cell has no centre "
                                 "square; expected an even number")
        if start is not None:
            check_symmetric(start, self.symmetry, f"--init {self.init}")

    def _check_upc(self) -> None:
        if self.pixel_um != RIG_PIXEL_UM:
            raise tp.DesignError(f"--pixel-um {self.pixel_um:g}: takes --optics rig (UPC's optics sample their own "
                                 "2 µm pixels)")
        if self.objective not in ("upc", "rings"):
            raise tp.DesignError(f"--optics upc takes --objective upc or rings, got {self.objective} (the Wiener "
                                 "objectives need the rig's sensor sampling: --optics rig)")
        if (self.cell_um, self.feature_um) != (upc.CELL_PX * upc.PUPIL_UM, upc.PUPIL_UM):
            raise tp.DesignError(f"--optics upc: UPC's sampling takes their {upc.CELL_PX * upc.PUPIL_UM:g} µm cell "
                                 f"of {upc.PUPIL_UM:g} µm features, got --cell-um {self.cell_um:g} --feature-um "
                                 f"{self.feature_um:g}")

    def _check_floor(self) -> None:
        _check_channels("--floor-channels", self.floor_channels)
        if self.upc_floor is None:
            if self.floor_uncropped:
                raise tp.DesignError("--floor-uncropped: takes --upc-floor")
            return
        self._check_bound("--upc-floor", self.upc_floor, " (the rings objective is UPC's statistic itself)")

    def _check_ceiling(self) -> None:
        if self.banding_ceiling is not None:
            self._check_bound("--banding-ceiling", self.banding_ceiling)

    def _check_arranged(self) -> None:
        if not (isinstance(self.arrangement, int) and 1 <= self.arrangement <= 16):
            raise tp.DesignError(f"--arrangement {self.arrangement}: expected an integer in 1 … 16 (tiles a side)")
        if self.tiling == "arranged" and (self.optics != "rig" or self.upc_floor is not None):
            raise tp.DesignError(f"--tiling arranged: takes --optics rig without --upc-floor (UPC's statistic is "
                                 f"taken on their random tilings), got --optics {self.optics}"
                                 + (f" --upc-floor {self.upc_floor:g}" if self.upc_floor is not None else ""))

    def _check_bound(self, option: str, ratio: float, why: str = "") -> None:
        """A ratio to the T-OLED's that bounds the rig's objectives: > 0, with wiener or crop in the rig's optics."""
        if not ratio > 0:
            raise tp.DesignError(f"{option} {ratio}: expected a ratio to the T-OLED's > 0")
        if self.objective not in ("wiener", "crop") or self.optics != "rig":
            raise tp.DesignError(f"{option}: takes --objective wiener or crop in --optics rig{why}, got --objective "
                                 f"{self.objective} --optics {self.optics}")

    @property
    def channel_index(self) -> list[int]:
        """The objective's channels as indices into the kernels' R, G, B."""
        return [CHANNELS.index(c) for c in self.channels]

    @property
    def tile_flips(self) -> bool:
        """Whether the simulator's turned tiling mirrors the tiles too (tile_flip): for a point-symmetric cell,
        whose quarter turns alone give two distinct tiles."""
        return self.symmetry == "c2"

    @property
    def objective_px(self) -> int:
        """The size of the kernels the objective scores: kernel_px, or its packed planes' (torch_psf.packed)."""
        return 2 * (self.kernel_px // 4) + 1 if self.packed else self.kernel_px

    @property
    def cell_px(self) -> int:
        return round(self.cell_um / self.feature_um)

    @property
    def open_squares(self) -> int:
        return round(self.open_fraction * self.cell_px ** 2)
