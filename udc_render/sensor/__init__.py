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

Radiometry (spectral form), per pixel p of colour c(p):

    E_k   = π L_k / (4 N²) · cos⁴θ            image-side irradiance (on-axis, object at infinity;
                                              cos⁴θ only when ``cos4_falloff``; tan θ = r / f)
    e(p)  = Σ_k E_k · A · t · Δλ_k · q_ck       electrons, A = pitch², t = exposure
    q_ck  = (1/Δλ_k) ∫_band QE_c(λ) λ/(h c) dλ  photon-weighted band mean of the quantum efficiency
    QE_c  = peak_qe · S_c(λ) / max_{c,λ} S      (S: camera sensitivities, linearly interpolated,
                                              0 outside their table)

q_ck is integrated exactly for the piecewise-linear S (Simpson on each sub-interval, exact for
the quadratic S·λ), so a band-constant radiance gives the exact electron count.

Signal chain, with R = white − black (DN) and g = gain · conversion_gain (DN per e⁻):

    noise = "poisson":  DN = black + g · min(Poisson(e) + N(0, σ_read²), FW)
    noise = "gaussian": w = g · e / R,   DN = black + R · min(w + N(0, λ_read + λ_shot · w), g FW / R)
    noise = "none":     DN = black + g · min(e, FW)

(noise is drawn around the unsaturated signal and the full well then caps the read-out signal, as
in Yang & Sankaranarayanan 2021, so a saturated pixel reads exactly black + g · FW: the white level
at gain 1 with the default conversion gain)
then DN is rounded to an integer, clipped to [0, white] (never wraps) and stored as uint16; dead
pixels are set to the black level and hot pixels to the white level. The clean mosaic is
black + g · min(e, FW) clipped to [0, white], unquantised (float32).
Brooks et al. 2019 ("Unprocessing images for learned raw denoising") sampling, natural logs:
    log λ_shot ~ U(log 1e-4, log 1.2e-2),  log λ_read ~ N(2.18 log λ_shot + 1.20, 0.26²).

Modules: config (SensorConfig), bayer (the RGGB convention, packing, bilinear demosaic), radiometry
(radiance ──► electrons), noise (electrons ──► DN), capture (the whole chain).
"""
from udc_render.sensor.bayer import (CHANNELS, SITE_COLOUR, SITES, demosaic_bilinear, mosaic_of, pack_rggb, rgb_to_rggb,
                                     site_colour, unpack_rggb)
from udc_render.sensor.capture import Capture, capture
from udc_render.sensor.config import SensorConfig, SensorError
from udc_render.sensor.noise import defect_map, expose, noise_lambdas, sample_brooks, sensor_lambdas
from udc_render.sensor.radiometry import (band_electron_weights, cos4_map, electrons_per_channel, electrons_rgb,
                                          electrons_spectral, photon_weights)

__all__ = ["CHANNELS", "SITES", "SITE_COLOUR", "Capture", "SensorConfig", "SensorError", "band_electron_weights",
           "capture", "cos4_map", "defect_map", "demosaic_bilinear", "electrons_per_channel", "electrons_rgb",
           "electrons_spectral", "expose", "mosaic_of", "noise_lambdas", "pack_rggb", "photon_weights", "rgb_to_rggb",
           "sample_brooks", "sensor_lambdas", "site_colour", "unpack_rggb"]
