"""The design's choices and limits, apart from the optimiser so that the CLI's parser reads them without torch."""
from __future__ import annotations

LITHOGRAPHY_UM = 1.5  # LTPS lithography's resolution: the smallest --feature-um allowed
DEFAULT_FEATURE_UM = 8.0  # UPC's pupil sampling (their 21 × 21 cell at 8 µm)
OBJECTIVES = ("wiener", "upc", "crop")
INITS = ("scatter", "toled")
CROP_PX = 192  # the objective 'crop's crop: `study layout --restore dep`'s
TILINGS = ("repeated", "turned")
