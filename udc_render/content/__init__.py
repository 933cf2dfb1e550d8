"""What scenes show: the monitor's image (files, built-ins, test patterns), procedural charts, and
spectra (monitor primaries, illuminants, colour-matching functions, band means)."""
