"""What the commands share: the one-line UserError, argument types, the scene and capture option
groups (one vocabulary for every command), and the check of an output folder before any work."""
from __future__ import annotations

import argparse
import math
import os
from dataclasses import replace
from pathlib import Path

from udc_render.errors import UdcError
from udc_render.scene import RENDER_PATHS, SAMPLERS, load_scene
from udc_render.scene.overrides import with_overrides
from udc_render.sensor import SensorConfig
from udc_render.synth_config import DEFAULT_FAR_FIELD_COARSE, DEFAULT_FAR_FIELD_THRESHOLD, MAX_GT_FRAMES


class UserError(UdcError):
    """A bad command-line value; printed as one line."""


class Parser(argparse.ArgumentParser):
    def error(self, message):
        raise UserError(f"{self.prog}: {message}")


def number(name: str, cast=float, lo: float = 0.0, lo_open: bool = True):
    """An argument type: a finite number > lo (≥ lo when not lo_open), naming the option when it is not."""
    def parse(text):
        try:
            v = cast(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"{name} must be a number, got '{text}'") from None
        if not (math.isfinite(v) and (v > lo if lo_open else v >= lo)):
            raise argparse.ArgumentTypeError(f"{name} must be {'>' if lo_open else '≥'} {lo:g}, got {text}")
        return v
    return parse


def positive(name: str, cast=float):
    return number(name, cast)


def non_negative(name: str):
    return number(name, float, 0.0, lo_open=False)


def field_rank(text):
    """--field-rank: a whole number ≥ 1, or 'exact' (every phase kernel: None)."""
    if text == "exact":
        return None
    try:
        value = int(text)
    except ValueError:
        value = 0
    if value < 1:
        raise argparse.ArgumentTypeError(f"--field-rank = {text!r}: expected a whole number ≥ 1 or 'exact'")
    return value


def defocus_tolerance(text):
    """--defocus-tolerance-px: a number of pixels ≥ 0.05, or 'off' (no defocus: None)."""
    if text == "off":
        return None
    try:
        value = float(text)
    except ValueError:
        value = math.nan
    if not (value >= 0.05 and math.isfinite(value)):
        raise argparse.ArgumentTypeError(f"--defocus-tolerance-px = {text!r}: expected a number of pixels ≥ 0.05 "
                                         "or 'off'")
    return value


def gt_frames(text):
    """--gt-frames: a whole number of glass frames averaged into the ground truth, or 'ideal' (noise-free)."""
    if text == "ideal":
        return text
    if not (text.isdigit() and 1 <= int(text) <= MAX_GT_FRAMES):
        raise argparse.ArgumentTypeError(f"--gt-frames = {text!r}: expected a whole number of frames from 1 to "
                                         f"{MAX_GT_FRAMES}, or 'ideal'")
    return int(text)


def far_field_threshold(text):
    """--far-field-threshold: a lost share from 0 to 1 (exclusive), or 'off' (the light past the window is lost:
    None)."""
    if text == "off":
        return None
    try:
        value = float(text)
    except ValueError:
        value = math.nan
    if not 0 <= value < 1:
        raise argparse.ArgumentTypeError(f"--far-field-threshold = {text!r}: expected a share from 0 to 1 (exclusive) "
                                         "or 'off'")
    return value


def field_print_sigma(text):
    """--field-print-sigma: a number of read-noise σ ≥ 0, or 'off' (always blend: None)."""
    if text == "off":
        return None
    try:
        value = float(text)
    except ValueError:
        value = math.nan
    if not 0 <= value < math.inf:
        raise argparse.ArgumentTypeError(f"--field-print-sigma = {text!r}: expected a number of σ ≥ 0 or 'off'")
    return value


def field_planes_rank(text):
    """--field-planes-rank: a whole number from 1 to optics.field_planes.MAX_RANK, or 'off' (the band path: None)."""
    from udc_render.optics.field_planes import MAX_RANK
    if text == "off":
        return None
    value = int(text) if text.isdigit() else 0
    if not 1 <= value <= MAX_RANK:
        raise argparse.ArgumentTypeError(f"--field-planes-rank = {text!r}: expected a whole number from 1 to "
                                         f"{MAX_RANK} or 'off'")
    return value


def far_field_coarse(text):
    """--far-field-coarse: an odd whole number of render pixels per coarse pixel."""
    if not (text.isdigit() and int(text) >= 1 and int(text) % 2 == 1):
        raise argparse.ArgumentTypeError(f"--far-field-coarse = {text!r}: expected an odd whole number ≥ 1")
    return int(text)


def add_far_field_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--far-field-threshold", type=far_field_threshold, default=argparse.SUPPRESS,
                   help="spectral form: lay the light a band's kernels send past their window on the sensor (a "
                        "far field at a coarse pitch, within the lens's acceptance; udc_render/optics/far_field.py) "
                        "when that lost share exceeds this, or 'off' (the light is lost) "
                        f"[{DEFAULT_FAR_FIELD_THRESHOLD:g}]")
    p.add_argument("--far-field-coarse", type=far_field_coarse, default=argparse.SUPPRESS,
                   help=f"render pixels per coarse pixel of the far field, odd [{DEFAULT_FAR_FIELD_COARSE}]")


def float_list(text):
    try:
        values = [float(t) for t in text.split(",") if t.strip()]
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected comma-separated numbers, got '{text}'") from None
    if not values or any(not (v > 0 and math.isfinite(v)) for v in values):
        raise argparse.ArgumentTypeError(f"wavelengths must be positive numbers, got '{text}'")
    return values


def float_pair(name: str):
    def parse(text):
        try:
            values = tuple(float(t) for t in text.split(","))
        except ValueError:
            raise argparse.ArgumentTypeError(f"{name} must be two numbers W,H, got '{text}'") from None
        if len(values) != 2 or any(not (v > 0 and math.isfinite(v)) for v in values):
            raise argparse.ArgumentTypeError(f"{name} must be two positive numbers W,H, got '{text}'")
        return values
    return parse


def odd_size(name: str):
    def parse(text):
        try:
            v = int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"{name} must be an odd integer ≥ 3, got '{text}'") from None
        if v < 3 or v % 2 == 0:
            raise argparse.ArgumentTypeError(f"{name} must be an odd integer ≥ 3 (centre at size//2), got {v}")
        return v
    return parse


def out_dir(path: Path, option: str = "--out") -> Path:
    """Create the output folder now, before any computation; a path that cannot be a writable folder
    (an existing file, a folder under a file, no permission) is a one-line UserError."""
    path = Path(path)
    if path.exists() and not path.is_dir():
        raise UserError(f"{option} {path}: exists and is not a folder")
    try:
        path.mkdir(parents=True, exist_ok=True)
    except OSError as e:
        raise UserError(f"{option} {path}: cannot create the folder ({e.strerror or e})") from None
    if not os.access(path, os.W_OK | os.X_OK):
        raise UserError(f"{option} {path}: the folder is not writable")
    return path


def add_display_argument(p: argparse.ArgumentParser, what: str, several: bool = False,
                         micrograph: str = "1 µm pixels, amplitude values", unset: str = "", **kw) -> None:
    """--display in the one vocabulary of every command (udc_render.optics.displays.load_display);
    `what`: what the command does with it; `several`: comma-separated, each item the same;
    `micrograph`: how a micrograph image's tile is read; `unset`: what no --display means [the default]."""
    from udc_render.optics.displays import ALLOWED
    each = "comma-separated displays, each " if several else ""
    unset = unset or kw.get("default")
    p.add_argument("--display", help=f"{what}: {each}{ALLOWED}. A micrograph image is a display of that layout "
                                     f"({micrograph}; T = 1, gain 1, d = 0; named by its file's stem)"
                                     + (f" [{unset}]" if unset else ""), **kw)


def add_scene_arguments(r: argparse.ArgumentParser, scene_option: bool = False) -> None:
    """Overrides of a scene file's settings (applied by scene_from_args); the scene itself is a
    positional argument, or --scene when `scene_option`."""
    if scene_option:
        r.add_argument("--scene", default="monitor", help="a scene file (TOML) or a built-in scene's name: a monitor "
                       "scene (one image per item) or a 3D one, room, hdr or a Mitsuba XML scene (one view per item) "
                       "[monitor]")
    else:
        r.add_argument("scene", help="a scene file (TOML) or a built-in scene's name (monitor, room, hdr)")
    samples = r.add_mutually_exclusive_group()
    samples.add_argument("--spp", type=positive("--spp", int), help="samples per pixel [the scene's render.spp]")
    samples.add_argument("--noise", type=positive("--noise"),
                         help="target relative RMS noise; spp is chosen from pilot renders (e.g. 0.01)")
    r.add_argument("--bands-nm", help="LOW:HIGH:STEP in nm [the scene's bands, default 400:700:10]")
    r.add_argument("--seed", type=int, help="render seed [the scene's render.seed, 0]")
    r.add_argument("--path", choices=RENDER_PATHS,
                   help="render path (udc_render/render/job.py): auto: analytic for the monitor alone through a "
                        "pinhole, rgb_matrix for the monitor through a thin lens, else spectral; analytic: the "
                        "exact pixel-area means of the panel, no Monte Carlo (monitor and pinhole only); "
                        "rgb_matrix: one Mitsuba RGB render of the panel's drive levels times the primaries' band "
                        "means (exact for the monitor alone); spectral: Mitsuba's spectral variant, the bands "
                        "rendered directly (3D scenes, XML) [the scene's render.path, auto]")
    r.add_argument("--sampler", choices=SAMPLERS,
                   help="Mitsuba's sampler for the Monte Carlo paths, spp rounded up as it needs: independent: "
                        "independent uniform samples; stratified: one jittered sample per cell of a square grid; "
                        "multijitter: multi-jittered (default); orthogonal: orthogonal-array jittered (a prime² "
                        "count); ldsampler: a low-discrepancy sequence; each pass is an independent "
                        "randomisation (study render: samplers) [the scene's render.sampler, multijitter]")
    r.add_argument("--image", help="what the monitor shows: an image file, builtin:NAME or pattern:NAME")
    r.add_argument("--sensor-px", type=float_pair("--sensor-px"), help="sensor width,height in pixels")
    r.add_argument("--pitch-um", type=positive("--pitch-um"), help="sensor pixel pitch in µm")
    r.add_argument("--quiet", action="store_true", help="no progress bar")


def scene_from_args(args):
    """The scene file with the command line's overrides applied (scene.overrides), and a Mitsuba XML
    scene's camera taken from its file (render.resolve_xml_camera: once, before kernels and render)."""
    from udc_render.render import resolve_xml_camera
    return resolve_xml_camera(with_overrides(
        load_scene(args.scene), spp=args.spp, noise=args.noise, seed=args.seed, path=getattr(args, "path", None),
        bands_nm=args.bands_nm, image=getattr(args, "image", None), sensor_px=args.sensor_px, pitch_um=args.pitch_um,
        sampler=args.sampler))


def add_capture_arguments(p: argparse.ArgumentParser) -> None:
    """Knobs shared by synth and dataset (demo: the defaults)."""
    from udc_render.pipeline import DEFAULT_DEFOCUS_TOLERANCE_PX
    from udc_render.profiles import DEFAULT_PROFILE, PHYSICAL_DISTANCE_MM, PROFILES
    add_display_argument(p, "the displays to capture through; the glass capture is always made too",
                         several=True, default="toled")
    p.add_argument("--profile", choices=tuple(PROFILES), default=DEFAULT_PROFILE,
                   help=f"paper: the paper's synthesis (form per_channel with its channel kernels, d = 0, "
                        f"heteroscedastic Gaussian noise, no defect pixels or FPN); physical: form "
                        f"spectral, d = {PHYSICAL_DISTANCE_MM:g} mm for the preset displays, dead and hot pixels, "
                        f"fixed-pattern noise (udc_render/profiles.py); --form, --channel-kernels and --distance-mm "
                        f"override it [{DEFAULT_PROFILE}]")
    p.add_argument("--distance-mm", type=non_negative("--distance-mm"),
                   help="display-to-lens distance d for every display [the profile's for the presets, a display "
                        "file's own]")
    p.add_argument("--form", choices=("spectral", "per_channel"),
                   help="spectral: K band kernels and camera sensitivities (physical); per_channel: the "
                        "paper's y = γ x ⊗ k + n with 3 channel kernels [the profile's]")
    add_channel_kernels_argument(p)
    add_sensor_arguments(p)
    p.add_argument("--gt-frames", type=gt_frames,
                   help="the ground truth: the mean of N glass captures at gain 1 (their noise σ/√N, as the paper "
                        "averaged 16), or 'ideal': noise-free [the profile's: 16]")
    p.add_argument("--stray-light", choices=("default", "off"),
                   help="stray light beyond diffraction (udc_render/optics/stray/): default, the evidence-backed "
                        "defaults (the P-OLED's haze), or off [the profile's: physical default, paper off]")
    p.add_argument("--exposure-s", type=positive("--exposure-s"),
                   help="exposure time [auto: the monitor's white at 0.8 of the full well through glass]")
    p.add_argument("--field-phases", type=positive("--field-phases", int), help="d > 0: phases per axis [4]")
    p.add_argument("--field-rank", type=field_rank, default=argparse.SUPPRESS,
                   help="d > 0: convolve with a rank-R basis of each band's phase kernels (R FFT pairs per band "
                        "instead of one per phase; the kernel residual is recorded), or 'exact' [4]")
    p.add_argument("--field-print-sigma", type=field_print_sigma, default=argparse.SUPPRESS,
                   help="d > 0: leave a display's field blend out (its mean kernel and power) when it can change no "
                        "pixel by more than this many σ of the read noise (udc_render/views.py field_print), or "
                        "'off' (always blend) [0.25]")
    p.add_argument("--field-planes-rank", type=field_planes_rank, default=argparse.SUPPRESS,
                   help="d > 0, a monitor's dataset items: the field blend through the monitor's 3 planes with this "
                        "many shared weight maps (3 FFTs each, in place of one per band and rank; "
                        "udc_render/optics/field_planes.py), or 'off' (the band path) [4]")
    p.add_argument("--precision", choices=("float32", "float64"), default="float32",
                   help="the optics' FFT convolutions: float32: single precision (default); float64: double "
                        "precision [float32]")
    p.add_argument("--defocus-tolerance-px", type=defocus_tolerance, default=argparse.SUPPRESS,
                   help="depth layers: the largest error in a pixel's blur-circle diameter, render pixels (fewer "
                        f"layers when larger; udc_render/optics/layers.py), or 'off' (every pixel in focus) "
                        f"[{DEFAULT_DEFOCUS_TOLERANCE_PX:g}]")
    add_far_field_arguments(p)


def add_channel_kernels_argument(p: argparse.ArgumentParser) -> None:
    from udc_render.pipeline import CHANNEL_KERNELS
    p.add_argument("--channel-kernels", choices=tuple(CHANNEL_KERNELS),
                   help="the per-channel form's 3 kernels: paper: the paper's recipe as printed, one wavelength "
                        "per channel (640, 520, 450 nm), its r, cubic down-sampling (= udc-render psf --method "
                        "paper); camera: the camera's sensitivities × D65 over the visible [the profile's: paper "
                        "for paper, camera for physical]")


def add_sensor_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--sensor-config", type=Path,
                   help="TOML file of sensor-model keys (gain is per display; see udc_render/sensor/config.py)")
    p.add_argument("--noise-model", choices=("poisson", "gaussian", "none"),
                   help="sensor noise (udc_render/sensor/noise.py): poisson: Poisson shot noise plus Gaussian read "
                        "noise in electrons; gaussian: its heteroscedastic Gaussian approximation (variance read + "
                        "shot × signal); none: the noise-free signal, quantised [the profile's: gaussian for paper; "
                        "else the sensor config's, poisson]")
    p.add_argument("--noise-seed", type=int, default=0, help="seed of the sensor noise [0]")
    p.add_argument("--no-cache", action="store_true", help="neither read nor write the kernel cache")
    p.add_argument("--cache-dir", type=Path, help="kernel cache folder [$UDC_RENDER_CACHE or ~/.cache/udc-render/psf]")


def synth_config(args):
    """SynthConfig from the capture options (absent options take the defaults)."""
    from udc_render.pipeline import SynthConfig
    sensor = SensorConfig()
    if getattr(args, "sensor_config", None) is not None:
        sensor = SensorConfig.from_toml(args.sensor_config)
    if getattr(args, "noise_model", None):
        sensor = replace(sensor, noise=args.noise_model)
    cache = getattr(args, "cache_dir", None)
    return SynthConfig(form=getattr(args, "form", None) or "spectral", sensor=sensor,
                       exposure_s=getattr(args, "exposure_s", None), precision=getattr(args, "precision", "float32"),
                       field_phases=getattr(args, "field_phases", None),
                       field_rank=getattr(args, "field_rank", SynthConfig.field_rank),
                       defocus_tolerance_px=getattr(args, "defocus_tolerance_px", SynthConfig.defocus_tolerance_px),
                       far_field_threshold=getattr(args, "far_field_threshold", SynthConfig.far_field_threshold),
                       far_field_coarse=getattr(args, "far_field_coarse", SynthConfig.far_field_coarse),
                       field_print_sigma=getattr(args, "field_print_sigma", SynthConfig.field_print_sigma),
                       field_planes_rank=getattr(args, "field_planes_rank", SynthConfig.field_planes_rank),
                       seed=getattr(args, "noise_seed", 0),
                       use_cache=not getattr(args, "no_cache", False),
                       kernel_cache=None if cache is None else str(cache))


def capture_setup(args, displays: str | None = None):
    """(SynthConfig, displays) of a capture command: the capture options under --profile (the default
    profile when the command has none); --form, --channel-kernels, --distance-mm, --noise-model,
    --gt-frames and --sensor-config win over the profile
    (udc_render.profiles). `displays`: the comma-separated displays [args.display]."""
    from udc_render.optics.displays import load_displays
    from udc_render.profiles import DEFAULT_PROFILE, resolve_profile
    return resolve_profile(getattr(args, "profile", DEFAULT_PROFILE), synth_config(args),
                           load_displays(displays if displays is not None else args.display),
                           form=getattr(args, "form", None), distance_mm=getattr(args, "distance_mm", None),
                           channel_kernels=getattr(args, "channel_kernels", None),
                           noise_model=getattr(args, "noise_model", None),
                           gt_frames=getattr(args, "gt_frames", None),
                           stray_light=getattr(args, "stray_light", None),
                           sensor_file=getattr(args, "sensor_config", None) is not None)
