"""Layout design: a differentiable PSF of a free-form display cell (torch_psf), UPC's layout metric in a mode
that follows their sampling (upc), ring statistics of an MTF and the Wiener restorability under a sensor's noise
(metrics). Torch is imported by torch_psf and upc only."""
