"""The design's choices and limits, apart from the optimiser so that the CLI's parser reads them without torch."""
from __future__ import annotations

LITHOGRAPHY_UM = 1.5  # LTPS lithography's resolution: the smallest --feature-um allowed
DEFAULT_FEATURE_UM = 8.0  # UPC's pupil sampling (their 21 × 21 cell at 8 µm)
OBJECTIVES = ("wiener", "upc", "crop", "rings")
OPTICS = ("rig", "upc")  # rig: the paper's rig, exact kernels; upc: UPC's sampling (udc_render.design.upc)
CHANNELS = "RGB"
INITS = ("scatter", "toled")
# The objective's sensor pitch: the paper's rig (3.1 µm, psf.Lens()); `study layout-trained`'s DeP restores packed
# planes of 12.4 µm (its 6.2 µm sensor's 2 × 2 Bayer blocks), where the designs rank otherwise (docs/guides/design.md)
RIG_PIXEL_UM = 3.1
CROP_PX = 192  # the objective 'crop's crop: `study layout --restore dep`'s
# The scene's RMS contrast per objective when --contrast is not given. wiener: 0.3 (not studied). crop: 1.0, the
# photographs' (astronaut's crops 0.6-1.6): from the T-OLED at 192 px its designs restore by DeP, paired against the
# turned T-OLED on 8 photo crops, -0.46 / -0.20 / -0.06 dB at contrast 0.3 / 0.5 / 1.0 (docs/guides/design.md)
CONTRAST_DEFAULTS = {"wiener": 0.3, "crop": 1.0, "upc": 0.3, "rings": 0.3}  # upc and rings do not use it
TILINGS = ("repeated", "turned", "arranged")  # arranged: a K × K pattern of D4 tiles, repeated (optimise doc)
ARRANGEMENT_TILES = 4  # --arrangement's K: the period 4 × 168 µm (docs/guides/design.md, the arranged tiling)
SYMMETRIES = ("none", "c2")  # the cell's point symmetry (udc_render.design.symmetry)
# `design --channel-step`'s default with --optics rig (DesignConfig's own 0.0: one wavelength per channel, the
# committed designs'): the camera's band at 40 nm. Against 5 nm its margins over the simulator's T-OLED err by
# 0.002 dB at 1.7 x one wavelength's CPU time; one wavelength per channel errs by 0.11 dB (study channel-step)
CHANNEL_STEP_NM = 40.0
