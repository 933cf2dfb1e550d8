"""One RAW capture: radiance (or the paper's per-channel RGB) ──► electrons ──► fixed-pattern noise, noise,
RGGB DN ──► defect pixels."""
from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field

import numpy as np

from udc_render.sensor.bayer import pack_rggb
from udc_render.sensor.config import SensorConfig, SensorError
from udc_render.sensor.defects import DefectConfig, apply_defects
from udc_render.sensor.fpn import FpnConfig
from udc_render.sensor.noise import expose
from udc_render.sensor.radiometry import electrons_per_channel, electrons_spectral, photon_weights


@dataclass(frozen=True)
class Capture:
    """One synthetic capture. mosaic_dn [H, W] uint16 (RGGB, with the sensor's defect pixels when
    there are any), clean_dn [H, W] float32 (noise-free, defect-free, free of fixed-pattern noise,
    unquantised, saturated like the sensor), packed_dn [4, H/2, W/2] uint16 (R, Gr, Gb, B; packed from mosaic_dn),
    electrons [H, W] float64 (mean collected e⁻ before the full well), params: every setting, the
    derived constants and the sampled noise parameters (JSON-serialisable)."""
    mosaic_dn: np.ndarray
    clean_dn: np.ndarray
    packed_dn: np.ndarray
    electrons: np.ndarray
    params: dict = field(default_factory=dict)




def capture(image: np.ndarray, edges_nm, sensor: SensorConfig, rng: np.random.Generator,
            input_pitch_um: float | None = None, defects: DefectConfig | None = None,
            fpn: FpnConfig | None = None) -> Capture:
    """Synthesise one RAW capture.

    image: [K, H, W] band-mean radiance (W·sr⁻¹·m⁻²·nm⁻¹) with edges_nm [K + 1] when
    sensor.form == 'spectral'; [3, H, W] linear RGB (edges_nm ignored, may be None) when
    'per_channel'. input_pitch_um: the image's pitch when it is the sensor pitch / an integer
    (block-mean binning; spectral form); None: already at the sensor pitch. H, W even.
    rng: the generator for the noise (its state before the draws is recorded in params).
    defects: dead and hot pixels applied to the quantised mosaic before packing (sensor.defects;
    None: none); they draw nothing from rng. fpn: fixed-pattern noise in the electron stage
    (sensor.fpn; None: none), its maps drawn from its own seed, not from rng.
    """
    _check_rng(rng)
    img = np.asarray(image)
    if sensor.form == "spectral":
        e = electrons_spectral(img, edges_nm, sensor, input_pitch_um)
    else:
        e = electrons_per_channel(img, sensor)
    clamped = int((img < 0).sum())  # input already checked finite; these were round-off, set to 0
    return capture_electrons(e, sensor, rng, defects, {
        "input_shape": list(img.shape), "input_pitch_um": input_pitch_um,
        "edges_nm": None if edges_nm is None or sensor.form != "spectral" else np.asarray(edges_nm, float).tolist(),
        "negative_values_clamped": clamped}, fpn)


def _check_rng(rng) -> None:
    if not isinstance(rng, np.random.Generator):
        raise SensorError(f"rng: {type(rng).__name__}: expected a numpy.random.Generator")


def capture_electrons(electrons: np.ndarray, sensor: SensorConfig, rng: np.random.Generator,
                      defects: DefectConfig | None = None, input_info: dict | None = None,
                      fpn: FpnConfig | None = None) -> Capture:
    """The capture of a mosaic of mean collected electrons [H, W] (RGGB sites, cos⁴ included):
    fixed-pattern noise, noise, quantisation, defect pixels, packing (capture's tail; the pipeline's fused
    optics give the electrons directly). input_info: how the electrons were made, recorded in params."""
    _check_rng(rng)
    state = rng.bit_generator.state
    e = np.asarray(electrons, dtype=np.float64)
    mosaic, clean, info = expose(e, sensor, rng, fpn)
    defect_info = None
    if defects is not None:
        mosaic, defect_info = apply_defects(mosaic, sensor, defects)
    params = {
        "sensor": dataclasses.asdict(sensor),
        "bayer": "RGGB: R (0,0), Gr (0,1), Gb (1,0), B (1,1); packed order R, Gr, Gb, B",
        "form": sensor.form,
        **(input_info or {}),
        "dn_per_electron": sensor.dn_per_electron,
        "range_dn": sensor.range_dn,
        "rng_state_before": state,
        **info,
        "defects": defect_info,
    }
    if sensor.form == "spectral":
        params["photon_weights_e_per_J"] = photon_weights(params["edges_nm"], sensor.camera, sensor.peak_qe).tolist()
        params["irradiance"] = "E = pi L / (4 N^2)" + (" cos^4" if sensor.cos4_falloff else "") + " (on-axis)"
    return Capture(mosaic, clean, pack_rggb(mosaic), e, params)
