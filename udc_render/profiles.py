"""Profiles: the paper's synthesis, or the physical one with the domain gaps the paper names.

The paper (Zhou et al. 2021, l.412) names what separates its synthetic data from its real captures:
bands from the display-to-lens distance, an inaccurate transmission, and impulse noise from dead or
over-exposed pixels. A profile fixes the synthesis choices that decide those gaps:

=========  ============================================  ===========================  ======================
profile    form                                          display-to-lens distance     sensor defects, FPN
=========  ============================================  ===========================  ======================
paper      ``per_channel``: the paper's y = γ x ⊗ k + n   0 (the display at the lens's none
           with its measured γ and channel kernels        principal plane)
           ``paper``: its recipe at 640 / 520 / 450 nm
physical   ``spectral``: band kernels, T(λ), the          PHYSICAL_DISTANCE_MM for the dead and hot pixels
(default)  camera's sensitivities                         preset displays              (sensor.defects), fixed-
                                                                                       pattern noise
                                                                                       (sensor.fpn defaults)
=========  ============================================  ===========================  ======================

Both profiles take the ground truth as the paper did, the mean of PAPER_GT_FRAMES = 16 glass captures at
gain 1 (l.235; SynthConfig.gt_frames, pipeline module doc): its synthetic pairs degraded those same averaged
captures and kept them as targets (l.258–260), so their residual noise (σ/4 of a glass frame) is in the
paper's real and synthetic targets alike. The paper's synthetic inputs also carry it, blurred and scaled by
γ, under the added noise n: per pixel its variance is γ²/16 of a gain-1 frame's against n's gain × γ of
it (T-OLED: 1 % of the input's noise variance, P-OLED 0.1 %), which the profile leaves out (its input is
the noise-free render). ``gt_frames = 'ideal'`` (``--gt-frames ideal``) keeps the noise-free ground truth.

Stray light (SynthConfig.stray_light, udc_render.optics.stray): the physical profile keeps the evidence-backed
defaults (the P-OLED's haze; room light, ghost, lens glare and the display's own light off for want of a
magnitude for the paper's rig), the paper profile has none (its synthesis has none).

The per-channel form's kernels (SynthConfig.channel_kernels): ``paper``, the paper's recipe as printed
(l.258–263: one wavelength per channel, its printed r, cubic down-sampling; psf.paper, the very kernels
of `udc-render psf --method paper`), or ``camera``, the camera's sensitivities × D65 over the visible
(psf.spectral.channel_kernels), which the physical profile keeps for an explicit ``--form per_channel``.
The paper profile's noise is the paper's heteroscedastic Gaussian (PAPER_NOISE: variance λ_read + λ_shot·w,
the λ of the simulated sensor at each display's gain); the physical profile keeps the sensor config's
(Poisson shot noise and Gaussian read noise in electrons). An explicit noise model or sensor config file
wins over the profile's noise. The transmission gap is the displays' T(λ) (optics.displays), the same
under both profiles.

resolve_profile applies a profile to a SynthConfig and the displays; explicit options win: a
``form`` replaces the profile's form, a ``channel_kernels`` its channel kernels, a noise model its noise, a
``distance_mm`` replaces the distance of every display (as
``--distance-mm`` always did). The profile's distance applies to the presets (toled, poled); a
display file keeps its own ``distance_mm`` (default 0). The per-channel form has no field-dependent
kernels (its channel kernels are at d = 0): under it the profile's distance is not applied, and an
explicit distance > 0 is refused. What the profile set and what the options overrode are recorded
in SynthConfig.profile, hence in synth.json (and a dataset's job.json).

PHYSICAL_DISTANCE_MM = 2 mm, chosen by `udc-render study realism` (banding rows): the paper sees
"periodic bands" of "low to moderate visibility" in its real data (l.498) from "a small distance"
between display and lens (l.499). d counts from the lens's principal plane, which lies inside the
lens, so a display touching the front element is still millimetres away. Through the 317 µm T-OLED
the bands' Michelson contrast is 1.0–1.3 % for any d from 0.5 to 5 mm (set by the aperture's
transform at 1/p, not by d); d sets only the period z_i p / d: 2466 px at 0.5 mm (less than one band
across the 2048-px frame), 616 px at 2 mm (3.3 bands: "bands", plural), 245 px at 5 mm. At 2 mm the
visibility (contrast / per-pixel noise at mid-grey) is 0.27: "low". The P-OLED's bands are invisible
at any d (contrast 3e-4). Uncertain from 0.5 to 5 mm: no distance is published.
"""
from __future__ import annotations

from dataclasses import asdict, dataclass, replace

from udc_render.errors import UdcError
from udc_render.optics.displays import Display
from udc_render.optics.stray import StrayLight
from udc_render.pipeline import SynthConfig
from udc_render.sensor.defects import DefectConfig
from udc_render.sensor.fpn import FpnConfig

PHYSICAL_DISTANCE_MM = 2.0
# The paper's noise (l.176–178): heteroscedastic Gaussian, variance λ_read + λ_shot·w, its λ measured on its
# camera (not printed): here the λ of the simulated sensor (sensor.noise.sensor_lambdas), at each display's gain.
PAPER_NOISE = {"noise": "gaussian", "lambda_source": "sensor"}
# The paper's ground truth: "we average the 16 repeated captured frames" through glass at gain 1 (l.235, Table 1);
# its synthetic pairs degrade those same captures and keep them as targets (l.258–260), so both profiles average.
PAPER_GT_FRAMES = 16


class ProfileError(UdcError):
    """An unknown profile or options it cannot honour; one line."""


@dataclass(frozen=True)
class Profile:
    """The synthesis choices a profile fixes (module doc)."""
    name: str
    form: str  # pipeline.FORMS
    channel_kernels: str  # the per-channel form's kernels (synth_config.CHANNEL_KERNELS)
    distance_mm: float  # display-to-lens distance of the preset displays
    defects: DefectConfig | None  # sensor defect pixels (None: none)
    noise: dict | None  # SensorConfig noise keys (None: the sensor config's)
    summary: str
    fpn: FpnConfig | None = None  # fixed-pattern noise: PRNU, DSNU, row/column offsets, dark current (None: none)
    gt_frames: int | None = None  # the ground truth: the mean of N glass frames (None: noise-free)
    stray_light: StrayLight = StrayLight()  # optics.stray: the evidence-backed defaults (the paper: all off)

    def sets(self) -> dict:
        """What the profile sets, as plain JSON values."""
        return {"form": self.form, "channel_kernels": self.channel_kernels, "distance_mm": self.distance_mm,
                "defects": None if self.defects is None else asdict(self.defects), "noise": self.noise,
                "fpn": None if self.fpn is None else asdict(self.fpn), "gt_frames": self.gt_frames,
                "stray_light": self.stray_light.describe()}


PROFILES = {
    "paper": Profile("paper", "per_channel", "paper", 0.0, None, PAPER_NOISE,
                     "the paper's synthesis: y = γ x ⊗ k + n (its 3 channel kernels, its γ), display at the lens, "
                     "no defect pixels, no fixed-pattern noise, its 16-frame ground truth",
                     gt_frames=PAPER_GT_FRAMES, stray_light=StrayLight.off()),
    "physical": Profile("physical", "spectral", "camera", PHYSICAL_DISTANCE_MM, DefectConfig(), None,
                        "band kernels and T(λ), the preset displays at the display-to-lens distance, "
                        "dead and hot pixels, fixed-pattern noise (PRNU, DSNU, row/column offsets, dark current), "
                        "the 16-frame ground truth", fpn=FpnConfig(), gt_frames=PAPER_GT_FRAMES),
}
DEFAULT_PROFILE = "physical"


def get_profile(name: str) -> Profile:
    if name not in PROFILES:
        raise ProfileError(f"--profile = {name!r}: expected one of {', '.join(PROFILES)}")
    return PROFILES[name]


def resolve_profile(name: str, cfg: SynthConfig, displays: list[Display], form: str | None = None,
                    distance_mm: float | None = None, channel_kernels: str | None = None,
                    noise_model: str | None = None, sensor_file: bool = False,
                    gt_frames: int | str | None = None,
                    stray_light: str | None = None) -> tuple[SynthConfig, list[Display]]:
    """(cfg with the profile's form, channel kernels, noise and defects and its record, the displays with
    their distance) under profile `name`; `form`, `distance_mm`, `channel_kernels` and `noise_model` are
    explicit options (None: not given), which win over the profile, as a sensor config file (`sensor_file`)
    does over its noise (module doc), and `gt_frames` (N, or 'ideal': the noise-free ground truth) over its
    ground truth, and `stray_light` ('default': optics.stray's defaults, 'off': none) over its stray light.
    `displays` as loaded, without a distance override; cfg.sensor with the options already applied."""
    p = get_profile(name)
    final_form = form if form is not None else p.form
    kernels = channel_kernels if channel_kernels is not None else p.channel_kernels
    options = {k: v for k, v in (("form", form), ("channel_kernels", channel_kernels), ("distance_mm", distance_mm),
                                 ("noise", noise_model), ("gt_frames", gt_frames), ("stray_light", stray_light))
               if v is not None}
    stray = p.stray_light if stray_light is None else StrayLight.off() if stray_light == "off" else StrayLight()
    frames = p.gt_frames if gt_frames is None else None if gt_frames == "ideal" else gt_frames
    if sensor_file:
        options["sensor_config"] = "a file"
    distance, applies_to, displays, notes = _distance(p, final_form, distance_mm, displays)
    sensor = cfg.sensor if p.noise is None or noise_model is not None or sensor_file else replace(cfg.sensor, **p.noise)
    record = {"name": p.name, "sets": p.sets(), "options": options,
              "applied": {"form": final_form, "channel_kernels": kernels, "distance_mm": distance,
                          "distance_applies_to": applies_to, "defects": p.sets()["defects"], "fpn": p.sets()["fpn"],
                          "gt_frames": frames, "stray_light": stray.describe(),
                          "noise": {"noise": sensor.noise, "lambda_source": sensor.lambda_source}}}
    if notes:
        record["notes"] = notes
    return replace(cfg, form=final_form, channel_kernels=kernels, sensor=sensor, defects=p.defects, fpn=p.fpn,
                   gt_frames=frames, stray_light=stray, profile=record), displays


def _distance(p: Profile, form: str, distance_mm: float | None, displays: list[Display]) -> tuple:
    """(distance, what it applies to, the displays at it, notes) under profile p, form and the option."""
    if distance_mm is not None:
        if form == "per_channel" and distance_mm > 0:
            raise ProfileError(f"--distance-mm {distance_mm:g} with form per_channel: the per-channel form (the "
                               "paper's) puts the display at the lens (d = 0); use --form spectral for d > 0")
        return (float(distance_mm), "every display (the option)",
                [d if d.is_glass else d.with_distance(float(distance_mm)) for d in displays], [])
    presets = "the preset displays (display files keep their own distance_mm)"
    if form == "per_channel":
        notes = (["the per-channel form has no field-dependent kernels: the profile's distance is not applied"]
                 if p.distance_mm > 0 else [])
        return 0.0, presets, displays, notes
    return (p.distance_mm, presets,
            [d.with_distance(p.distance_mm) if d.source == "preset" and not d.is_glass else d for d in displays], [])


def describe(record: dict | None) -> str:
    """One line for a command's report: the profile and what it set ("(option)": set by an option)."""
    if not record:
        return "no profile"
    a, o = record["applied"], record["options"]
    d = a["defects"]
    defects = "none" if d is None else (f"dead {d['dead_fraction']:g}, hot {d['hot_fraction']:g} "
                                        f"({d['hot_dark_e_per_s']:g} e-/s), seed {d['seed']}")
    f = a.get("fpn")
    fpn = "none" if f is None else (f"PRNU {f['prnu']:g}, DSNU {f['dsnu_e']:g} e-, rows/columns {f['row_offset_e']:g}/"
                                    f"{f['column_offset_e']:g} e-, dark {f['dark_current_e_per_s']:g} e-/s, "
                                    f"seed {f['seed']}")
    mark = {k: " (option)" if k in o else "" for k in ("form", "channel_kernels", "distance_mm", "noise", "gt_frames",
                                                          "stray_light")}
    n = a.get("gt_frames")
    gt = "noise-free" if n is None else f"the mean of {n} glass frame{'s' if n > 1 else ''}"
    stray = stray_summary(a.get("stray_light"))
    kernels = (f" (channel kernels {a['channel_kernels']}{mark['channel_kernels']})"
               if a["form"] == "per_channel" else "")
    return (f"profile {record['name']}: form {a['form']}{mark['form']}{kernels}, display-to-lens distance "
            f"{a['distance_mm']:g} mm{mark['distance_mm']} for {a['distance_applies_to']}, noise {a['noise']['noise']}"
            f"{mark['noise']}, defect pixels: {defects}, fixed-pattern noise: {fpn}, "
            f"ground truth: {gt}{mark['gt_frames']}, "
            f"stray light: {stray}{mark['stray_light']}")


def stray_summary(knobs: dict | None) -> str:
    """The stray-light effects that are on (StrayLight.describe() knobs), in a few words."""
    if not knobs:
        return "none"
    on = []
    if knobs["room_illuminance_lux"]:
        on.append(f"room {knobs['room_illuminance_lux']:g} lx on the screen (R {knobs['screen_reflectance']:g})")
    if knobs["lens_reflectance"]:
        on.append(f"ghost (lens R {knobs['lens_reflectance']:g})")
    if knobs["lens_glare"]:
        on.append(f"lens glare {knobs['lens_glare']:g}")
    haze = {k: v for k, v in knobs["haze"].items() if v > 0}
    if haze:
        on.append("haze " + ", ".join(f"{k} {v:g}" for k, v in haze.items()))
    if knobs["display_luminance_cd_m2"]:
        on.append(f"display light {knobs['display_luminance_cd_m2']:g} cd/m²")
    return ", ".join(on) or "none"
