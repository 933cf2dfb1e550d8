"""The sensor: band radiance at the sensor plane ──► RGGB RAW mosaic in DN (docs/PHYSICS.md §1, §2, §5).

Conventions
-----------
* Bayer pattern **RGGB**: R at (row 0, col 0), Gr at (0, 1), Gb at (1, 0), B at (1, 1), repeated
  with period 2. Packed RAW is ``[4, H/2, W/2]`` in the order (R, Gr, Gb, B).
* Input (spectral form): ``[K, H, W]`` band-mean radiance L_k in W·sr⁻¹·m⁻²·nm⁻¹ at the sensor
  pitch (already blurred and multiplied by the display transmission by the optics stage), with band
  edges ``edges_nm`` [K + 1]; radiance is taken as constant within a band.
* Input (per-channel form, the paper's ``y = γ_c x_c``): ``[3, H, W]`` linear R, G, B in normalised
  units, where x = 1 at γ = 1 fills the full well (and, at gain 1 with the default conversion gain,
  the white level).

    radiance L_k ──► electrons e(p) = Σ_k π L_k / (4 N²) [cos⁴θ] · A · t · Δλ_k · q_ck   (radiometry.py)
    electrons ──► DN: fixed-pattern noise (PRNU gain map, dark current, DSNU and row/column
                  offsets; optional, the same maps in every capture)                     (fpn.py)
                  Poisson + read noise (or heteroscedastic Gaussian), full well, quantise,
                  black and white levels                                               (noise.py)
    DN ──► DN: dead and hot pixels, the same map in every capture (optional)         (defects.py)

Modules: config (SensorConfig), bayer (the RGGB convention, packing, bilinear demosaic), radiometry
(radiance ──► electrons), noise (electrons ──► DN), fpn (FpnConfig: fixed-pattern noise), defects
(DefectConfig: dead and hot pixels), readout (the arithmetic of noise, fpn and defects on any array namespace:
the one definition the numpy synthesis and the online degradation in torch, restore.degrade_sensor, share),
capture (the whole chain), frames (the mean of N frames: the averaged ground truth).
"""
from udc_render.sensor import readout
from udc_render.sensor.bayer import (
    CHANNELS,
    SITE_COLOUR,
    SITES,
    bilinear_quarters,
    demosaic_bilinear,
    mosaic_of,
    pack_rggb,
    rgb_to_rggb,
    site_colour,
    unpack_rggb,
)
from udc_render.sensor.capture import Capture, capture, capture_electrons
from udc_render.sensor.config import SensorConfig, SensorError
from udc_render.sensor.defects import DefectConfig, DefectError, apply_defects, defect_levels, defect_map
from udc_render.sensor.fpn import FpnConfig, FpnError, FpnMaps, fpn_maps, fpn_normals
from udc_render.sensor.noise import expose, noise_lambdas, sample_brooks, sensor_lambdas
from udc_render.sensor.radiometry import (
    band_electron_weights,
    cos4_map,
    electrons_per_channel,
    electrons_rgb,
    electrons_spectral,
    photon_weights,
)

__all__ = ["CHANNELS", "SITES", "SITE_COLOUR", "Capture", "DefectConfig", "DefectError", "FpnConfig", "FpnError",
           "FpnMaps", "SensorConfig", "SensorError", "apply_defects", "band_electron_weights", "bilinear_quarters",
           "capture", "capture_electrons", "cos4_map", "defect_levels", "defect_map", "demosaic_bilinear",
           "electrons_per_channel", "electrons_rgb", "electrons_spectral", "expose", "fpn_maps", "fpn_normals",
           "mosaic_of", "noise_lambdas", "pack_rggb", "photon_weights", "readout", "rgb_to_rggb", "sample_brooks",
           "sensor_lambdas", "site_colour", "unpack_rggb"]
