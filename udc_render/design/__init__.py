"""Layout design (issue 48): a differentiable PSF of a free-form display cell (torch_psf), UPC's layout metric in a
mode that follows their sampling (upc), ring statistics of an MTF and the Wiener restorability under a sensor's
noise (metrics, mtf), the cells the designer and the layout study take (cells), the finite crop's share (crop), the
search (optimise) with its UPC floor (floor) and its banding ceiling (bands), and one resumable run (job). options
and metrics import no torch (the CLI's parser and the layout study read them)."""
