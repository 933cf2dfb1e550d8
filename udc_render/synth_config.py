"""The synthesis settings (SynthConfig) of udc_render.pipeline and its error; re-exported there.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

from udc_render.errors import UdcError
from udc_render.optics.field_planes import MAX_RANK as PLANES_MAX_RANK
from udc_render.optics.stray import StrayLight
from udc_render.sensor import DefectConfig, FpnConfig, SensorConfig
from udc_render.sensor.frames import MAX_FRAMES as MAX_GT_FRAMES

FORMS = ("spectral", "per_channel")
# The per-channel form's 3 kernels (synth_kernels.display_channel_kernels), each with its record in capture.json
CHANNEL_KERNELS = {"paper": "the paper's recipe as printed at 640 / 520 / 450 nm (psf.paper, psf --method paper)",
                   "camera": "camera × D65 weighted over the visible (psf.spectral.channel_kernels)"}
EXPOSURE_FILL = 0.8
EXPOSURE_PERCENTILE = 99.5
# Depth layers: the largest error in a pixel's blur-circle diameter, in render pixels (optics.layers).
# `study capture` (layers: a near ramp over a far plane, against the per-pixel reference): the error at the
# near object's edge falls linearly with the tolerance, 0.68 % at 1 px (8 layers; 0.36 % at 0.5 px with 13,
# 1.6 % at 4 px with 3). 1 px keeps the built-in room at 2048 × 1024 within 3× its one-layer optics
# (benchmarks/bench_layers.py: 0.5 px gives it 3 layers and 3.7×).
DEFAULT_DEFOCUS_TOLERANCE_PX = 1.0
# Light past the kernel window (optics.far_field): the far field is added to a view's band whose lost share (its
# kernels' energy outside the core window) exceeds the threshold; its coarse pixel is an odd number of render
# pixels. Chosen by `study capture` (far_field rows; docs/concepts/defaults.md).
DEFAULT_FAR_FIELD_THRESHOLD = 0.005
DEFAULT_FAR_FIELD_COARSE = 15



class SynthError(UdcError):
    """Settings the synthesis cannot honour; one line."""


@dataclass(frozen=True)
class SynthConfig:
    """Knobs of the synthesis (defaults: the paper's rig; every one is recorded in the sidecars)."""
    form: str = "spectral"
    channel_kernels: str = "camera"  # the per-channel form's kernels (CHANNEL_KERNELS)
    sensor: SensorConfig = field(default_factory=SensorConfig)  # gain is replaced by each display's
    exposure_s: float | None = None  # None: auto (module doc)
    precision: str = "float32"  # optics FFTs
    kernel_precision: str = "float32"
    field_phases: int | None = None  # d > 0: phases per axis (None: the engine's default, 4)
    blend: str = "source"
    # d > 0: rank of each band's phase-kernel basis (None: every phase). 4, the lowest rank that keeps the T-OLED
    # flat field's first harmonic within 5 % of the exact series P(s) at d = 2–16 mm (`study banding`, issue 29):
    # 0.974 / 0.976 / 1.020 / 0.988 at 2 / 4 / 8 / 16 mm (rank 2: 0.96 / 0.93 / 0.86 / 0.72, rank 3: 0.96 / 0.93 /
    # 0.91 / 0.96; a basis that drops the kernels' phase-dependent shape smooths the bands by the PSF's MTF).
    # Cost: a 2048 × 1024 synthesis 1.35–1.5× rank 2's (benchmarks/bench_banding_rank.py; docs/concepts/defaults).
    field_rank: int | None = 4
    seed: int = 0
    use_cache: bool = True
    kernel_cache: str | None = None  # kernel cache folder (None: psf.cache's default); how, not what: not recorded
    defects: DefectConfig | None = None  # dead and hot pixels of the sensor (None: none)
    # fixed-pattern noise of the sensor: PRNU, DSNU, rows/columns, dark current (None: none)
    fpn: FpnConfig | None = None
    # Stray light beyond the diffraction model (optics.stray: room light, ghost, lens glare, display haze,
    # the display's own light; each off at 0 or None): the evidence-backed defaults, the paper profile all off
    stray_light: StrayLight = field(default_factory=StrayLight)
    # Depth layers (optics.layers): largest blur-diameter error, render px; None: no defocus at all
    # (every pixel in focus, the kernels of the focus distance)
    defocus_tolerance_px: float | None = DEFAULT_DEFOCUS_TOLERANCE_PX
    bright_split: bool = True  # very bright pixels convolved apart in float64 (bright_pixels)
    # Light past the kernel window (optics.far_field, spectral form): the far field is added to a band whose lost
    # share exceeds the threshold (None: never, the light is lost); coarse: render pixels per coarse pixel (odd)
    far_field_threshold: float | None = DEFAULT_FAR_FIELD_THRESHOLD
    far_field_coarse: int = DEFAULT_FAR_FIELD_COARSE
    # d > 0: the field blend is left out of a view (its mean kernel and mean power taken) when what it could change
    # in any pixel (a bound: views.field_print) is at most this many σ of the read noise, the least noise of any
    # pixel (Poisson noise only; None: always blended). 0.25: on the paper's frame at 2 mm the P-OLED's blend is left
    # out (bound 0.11 σ; measured at most 0.004 σ), the T-OLED's kept (bound 19 σ); benchmarks/bench_field_knobs.py
    field_print_sigma: float | None = 0.25
    # d > 0, a monitor through its three planes: the rank-r field blend's K·r weight maps replaced by their first J
    # shared maps (optics.field_planes: 3J forward FFTs where K·r are made; dataset workers, kernels from
    # prepare_kernels); None: the band path. 4: on the paper's frame at 2 mm the T-OLED's electrons move by at most
    # 0.07 σ of the read noise against the band path, at 1/8 of its time (benchmarks/bench_field_knobs.py --planes)
    field_planes_rank: int | None = 4
    # The ground truth as the paper took it (l.235): the mean of N glass captures at gain 1 (sensor.frames:
    # temporal noise σ/√N, quantised, saturating); None: the ideal noise-free ground truth (pipeline module doc)
    gt_frames: int | None = None
    # The profile that chose form, distance and defects (udc_render.profiles.resolve_profile): a JSON
    # record {name, sets, options, applied}, kept in synth.json; None when no profile was used.
    profile: dict | None = field(default=None, hash=False)

    def __post_init__(self):
        if self.form not in FORMS:
            raise SynthError(f"form = {self.form!r}: expected one of {', '.join(FORMS)}")
        if self.channel_kernels not in CHANNEL_KERNELS:
            raise SynthError(f"channel_kernels = {self.channel_kernels!r}: "
                             f"expected one of {', '.join(CHANNEL_KERNELS)}")
        if self.defects is not None and not isinstance(self.defects, DefectConfig):
            raise SynthError(f"defects = {self.defects!r}: expected a sensor.defects.DefectConfig or None")
        if self.fpn is not None and not isinstance(self.fpn, FpnConfig):
            raise SynthError(f"fpn = {self.fpn!r}: expected a sensor.fpn.FpnConfig or None")
        if not isinstance(self.stray_light, StrayLight):
            raise SynthError(f"stray_light = {self.stray_light!r}: expected an optics.stray.StrayLight")
        if self.exposure_s is not None and not (self.exposure_s > 0 and math.isfinite(self.exposure_s)):
            raise SynthError(f"exposure_s = {self.exposure_s!r}: expected a positive number of seconds or auto")
        g = self.gt_frames
        if g is not None and (isinstance(g, bool) or not isinstance(g, int) or not 1 <= g <= MAX_GT_FRAMES):
            raise SynthError(f"gt_frames = {g!r}: expected a whole number of frames from 1 to {MAX_GT_FRAMES}, or None "
                             "(the noise-free ground truth)")
        ft = self.far_field_threshold
        if ft is not None and (isinstance(ft, bool) or not isinstance(ft, (int, float)) or not 0 <= ft < 1):
            raise SynthError(f"far_field_threshold = {ft!r}: expected a lost share from 0 to 1 (exclusive), "
                             "or None (off)")
        fc = self.far_field_coarse
        if isinstance(fc, bool) or not isinstance(fc, int) or fc < 1 or fc % 2 == 0:
            raise SynthError(f"far_field_coarse = {fc!r}: expected an odd whole number of render pixels ≥ 1")
        fp = self.field_print_sigma
        if fp is not None and (isinstance(fp, bool) or not isinstance(fp, (int, float)) or not 0 <= fp < math.inf):
            raise SynthError(f"field_print_sigma = {fp!r}: expected a number of read-noise σ ≥ 0, or None "
                             "(always blend)")
        jr = self.field_planes_rank
        if jr is not None and (isinstance(jr, bool) or not isinstance(jr, int) or not 1 <= jr <= PLANES_MAX_RANK):
            raise SynthError(f"field_planes_rank = {jr!r}: expected a whole number from 1 to {PLANES_MAX_RANK}, or "
                             "None (the band path)")
        tol = self.defocus_tolerance_px
        if tol is not None and (isinstance(tol, bool) or not isinstance(tol, (int, float)) or not math.isfinite(tol)
                                or not tol >= 0.05):
            raise SynthError(f"defocus_tolerance_px = {tol!r}: expected a number of pixels ≥ 0.05, "
                             "or None (no defocus)")
