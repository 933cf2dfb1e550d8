"""The `udc-render` command line.

    udc-render psf --display {none,toled,poled,PATH} --wavelengths-nm 450,520,640 --out DIR
    udc-render render SCENE --out DIR [--spp N | --noise 0.01] [--bands-nm 400:700:10]
    udc-render study {psf,render,capture} --out DIR [--quick]
    udc-render synth SCENE --display toled[,poled,FILE] --out DIR;  udc-render demo [--out DIR]

User errors print one line naming the argument, value and what is allowed, and exit 2;
no traceback.
"""
from __future__ import annotations

import argparse
import json
import math
import sys
import warnings
from pathlib import Path

import numpy as np

from psf import Lens, MicrographLayout, compute_kernels, layouts
from psf.banding import banding_profile
from psf.cache import cached
from psf.engine import DEFAULT_FIELD_PHASES, METHODS, PAPER_SENSOR_UM, PRECISIONS, AliasingWarning, UnderSamplingWarning
from psf.layouts import LayoutError
from psf.lens import LensError
from psf.engine import PSFError
from psf.pupil import MASK_RASTERS
from psf.spectral import auto_step_nm, band_kernels, channel_kernels, load_weight

from udc_render.display_image import DisplayImageError
from udc_render.displays import DisplayError
from udc_render.optics import OpticsError
from udc_render.scene import RENDER_PATHS, SceneError
from udc_render.render import RenderError
from udc_render.sensor import SensorError
from udc_render.spectra import SpectrumError
from udc_render.synth import SynthError

USER_ERRORS = (PSFError, LayoutError, LensError, SceneError, SpectrumError, DisplayImageError, DisplayError,
               OpticsError, SensorError, SynthError, RenderError)

# Subcommands that live in their own modules: each has register(subparsers) -> {name: run(args) -> int}.
COMMAND_MODULES = ("udc_render.synth_cli", "udc_render.dataset", "udc_render.calibrate", "restore.cli")


class UserError(Exception):
    """A bad command-line value; printed as one line."""


class _Parser(argparse.ArgumentParser):
    def error(self, message):
        raise UserError(f"{self.prog}: {message}")


def _positive(name, cast=float):
    def parse(text):
        try:
            v = cast(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"{name} must be a number, got '{text}'") from None
        if not (v > 0 and math.isfinite(v)):
            raise argparse.ArgumentTypeError(f"{name} must be > 0, got {text}")
        return v
    return parse


def _non_negative(name):
    def parse(text):
        try:
            v = float(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"{name} must be a number, got '{text}'") from None
        if not (v >= 0 and math.isfinite(v)):
            raise argparse.ArgumentTypeError(f"{name} must be ≥ 0, got {text}")
        return v
    return parse


def _float_list(text):
    try:
        values = [float(t) for t in text.split(",") if t.strip()]
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected comma-separated numbers, got '{text}'") from None
    if not values or any(not (v > 0 and math.isfinite(v)) for v in values):
        raise argparse.ArgumentTypeError(f"wavelengths must be positive numbers, got '{text}'")
    return values


def _float_pair(name):
    def parse(text):
        try:
            values = tuple(float(t) for t in text.split(","))
        except ValueError:
            raise argparse.ArgumentTypeError(f"{name} must be two numbers W,H, got '{text}'") from None
        if len(values) != 2 or any(not (v > 0 and math.isfinite(v)) for v in values):
            raise argparse.ArgumentTypeError(f"{name} must be two positive numbers W,H, got '{text}'")
        return values
    return parse


def _bands(text):
    try:
        bands = [tuple(float(v) for v in b.split("-")) for b in text.split(",") if b.strip()]
    except ValueError:
        raise argparse.ArgumentTypeError(f"bands must look like 400-500,500-600, got '{text}'") from None
    if not bands or any(len(b) != 2 or not 0 < b[0] < b[1] for b in bands):
        raise argparse.ArgumentTypeError(f"bands must look like 400-500,500-600 with lo < hi, got '{text}'")
    return bands


def _odd_size(text):
    try:
        v = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"size must be an odd integer ≥ 3, got '{text}'") from None
    if v < 3 or v % 2 == 0:
        raise argparse.ArgumentTypeError(f"size must be an odd integer ≥ 3 (centre at size//2), got {v}")
    return v


def add_scene_arguments(r: argparse.ArgumentParser) -> None:
    """Overrides of a scene file's settings (applied by scene_from_args)."""
    samples = r.add_mutually_exclusive_group()
    samples.add_argument("--spp", type=_positive("--spp", int), help="samples per pixel [the scene's render.spp]")
    samples.add_argument("--noise", type=_positive("--noise"),
                         help="target relative RMS noise; spp is chosen from pilot renders (e.g. 0.01)")
    r.add_argument("--bands-nm", help="LOW:HIGH:STEP in nm [the scene's bands, default 400:700:10]")
    r.add_argument("--seed", type=int, help="render seed [the scene's render.seed, 0]")
    r.add_argument("--path", choices=RENDER_PATHS, help="render path [auto: rgb_matrix for the monitor alone]")
    r.add_argument("--image", help="what the monitor shows: an image file, builtin:NAME or pattern:NAME")
    r.add_argument("--sensor-px", type=_float_pair("--sensor-px"), help="sensor width,height in pixels")
    r.add_argument("--pitch-um", type=_positive("--pitch-um"), help="sensor pixel pitch in µm")
    r.add_argument("--quiet", action="store_true", help="no progress bar")


def build_parser() -> argparse.ArgumentParser:
    parser = _Parser(prog="udc-render", description="Physically based under-display camera simulation.")
    sub = parser.add_subparsers(dest="command", required=True, parser_class=_Parser)

    p = sub.add_parser("psf", help="wave-optics PSF kernels of a display in front of a lens")
    p.add_argument("--display", default="toled",
                   help="none (bare lens), toled, poled, or a micrograph file (PNG/TIFF/EXR) [toled]")
    spec = p.add_mutually_exclusive_group()
    spec.add_argument("--wavelengths-nm", type=_float_list, default=[450.0, 520.0, 640.0],
                      help="monochromatic kernels at these wavelengths [450,520,640]")
    spec.add_argument("--bands-nm", type=_bands, help="band kernels, e.g. 400-500,500-600,600-700")
    spec.add_argument("--camera", help="channel-effective kernels for a colour-science camera "
                                       "('Nikon 5100 (NPL)', 'Sigma SDMerill (NPL)') or a CSV of sensitivities")
    p.add_argument("--band-step-nm", type=_positive("--band-step-nm"), default=None,
                   help="wavelength step inside a band or channel [auto: λ_lo / size, 1.6 nm at 400 nm, 255 px]")
    p.add_argument("--weight", default="E",
                   help="weight spectrum for --bands-nm and --camera: E (flat), a colour-science illuminant "
                        "such as D65, or a CSV (wavelength_nm, weight) [E]")
    p.add_argument("--distance-mm", type=_non_negative("--distance-mm"), default=0.0,
                   help="display-to-lens distance d; 0 = principal-plane model [0]")
    p.add_argument("--pixel-um", type=_positive("--pixel-um"), default=3.1, help="sensor pixel pitch [3.1]")
    p.add_argument("--size", type=_odd_size, default=255, help="kernel size in pixels, odd [255]")
    p.add_argument("--focal-length-um", type=_positive("--focal-length-um"), default=6000.0)
    p.add_argument("--aperture-um", type=_positive("--aperture-um"), default=3333.0)
    p.add_argument("--focus-distance-mm", type=_positive("--focus-distance-mm"), default=math.inf)
    p.add_argument("--object-distance-mm", type=_positive("--object-distance-mm"), default=math.inf)
    p.add_argument("--method", choices=METHODS, default="mft", help="Fraunhofer transform [mft]")
    p.add_argument("--pupil-samples", type=_positive("--pupil-samples", int), default=None,
                   help="samples across the aperture [auto: ≥ 1024 and alias-free]")
    p.add_argument("--field-phases", type=_positive("--field-phases", int), default=None,
                   help="mask shifts per axis over one display period, d > 0 only [4]")
    p.add_argument("--sensor-um", type=_float_pair("--sensor-um"), default=PAPER_SENSOR_UM,
                   help="image width,height in µm: field phases span what it sees of a banding period "
                        "[3174.4,1587.2, the paper's 2048×1024 × 1.55 µm]")
    p.add_argument("--precision", choices=tuple(PRECISIONS), default="float32")
    p.add_argument("--mask-raster", choices=MASK_RASTERS, default="band_limited")
    p.add_argument("--micrograph-pixel-um", type=_positive("--micrograph-pixel-um"), default=1.0,
                   help="pixel size of a micrograph display in µm [1.0]")
    p.add_argument("--micrograph-values", choices=("amplitude", "intensity"), default="amplitude")
    p.add_argument("--tile-rotation", action="store_true", help="rotate each micrograph tile randomly")
    p.add_argument("--seed", type=int, default=0, help="seed of the tile rotations [0]")
    p.add_argument("--no-cache", action="store_true", help="neither read nor write the kernel cache")
    p.add_argument("--out", type=Path, default=Path("out/psf"), help="output folder [out/psf]")

    r = sub.add_parser("render", help="render a scene to band radiance images with Mitsuba 3")
    r.add_argument("scene", help="a scene file (TOML) or the name of one in scenes/ (monitor, room, hdr)")
    r.add_argument("--out", type=Path, default=Path("out/render"), help="output folder [out/render]")
    add_scene_arguments(r)

    s = sub.add_parser("study", help="error-versus-run-time studies of the approximation knobs")
    s.add_argument("what", choices=("psf", "render", "capture"))
    s.add_argument("--out", type=Path, default=Path("out/study"))
    s.add_argument("--quick", action="store_true", help="a reduced grid (smoke run)")

    import importlib
    parser.runners = {"psf": run_psf, "render": run_render, "study": run_study}
    for name in COMMAND_MODULES:
        parser.runners.update(importlib.import_module(name).register(sub))
    return parser


def make_display(args):
    if args.display == "none":
        return None
    if args.display in layouts.BUILTIN:
        return layouts.BUILTIN[args.display]()
    path = Path(args.display)
    if path.suffix.lower() not in (".png", ".tif", ".tiff", ".exr"):
        raise UserError(f"--display: '{args.display}' is not none, toled, poled or a .png/.tif/.tiff/.exr file")
    return MicrographLayout.load(path, args.micrograph_pixel_um, args.micrograph_values, args.tile_rotation, args.seed)


def run_psf(args) -> int:
    from tqdm import tqdm
    from .fileio import save_exr, save_json, save_npz
    from .plots import plot_banding, plot_kernels, plot_mtf

    display = make_display(args)
    lens = Lens(args.focal_length_um, args.aperture_um, args.focus_distance_mm, args.object_distance_mm)
    common = dict(pixel_um=args.pixel_um, size_px=args.size, distance_mm=args.distance_mm,
                  field_phases=args.field_phases, method=args.method, pupil_samples=args.pupil_samples,
                  precision=args.precision, mask_raster=args.mask_raster, sensor_um=args.sensor_um)
    phases = (args.field_phases or DEFAULT_FIELD_PHASES) ** 2 if args.distance_mm > 0 and display is not None else 1
    with warnings.catch_warnings(record=True) as caught, tqdm(desc="psf kernels", unit="kernel", disable=None) as bar:
        warnings.simplefilter("always", AliasingWarning)
        warnings.simplefilter("always", UnderSamplingWarning)
        common["progress"] = bar.update
        if args.bands_nm:
            bar.total = phases * sum(math.ceil((hi - lo) / (args.band_step_nm or auto_step_nm(lo, args.size)) - 1e-9)
                                     for lo, hi in args.bands_nm)
            ks, hit = cached(band_kernels, "band", display, lens, not args.no_cache, bands_nm=args.bands_nm,
                             step_nm=args.band_step_nm, weight=load_weight(args.weight), weight_name=args.weight,
                             **common)
        elif args.camera:
            ks, hit = cached(channel_kernels, "channel", display, lens, not args.no_cache, camera=args.camera,
                             illuminant=args.weight, step_nm=args.band_step_nm, **common)
        else:
            bar.total = phases * len(args.wavelengths_nm)
            ks, hit = cached(compute_kernels, "mono", display, lens, not args.no_cache,
                             wavelengths_nm=args.wavelengths_nm, **common)
    for w in caught:
        if issubclass(w.category, AliasingWarning) and args.pupil_samples is not None:
            raise UserError(f"--pupil-samples is too coarse for the requested window: {w.message}")
    for w in {str(w.message) for w in caught}:
        print(f"warning: {w}", file=sys.stderr)

    out = args.out
    out.mkdir(parents=True, exist_ok=True)
    arrays = dict(kernels=ks.kernels, wavelengths_nm=ks.wavelengths_nm, pixel_um=np.float64(ks.pixel_um),
                  energy_outside=ks.energy_outside, transmittance=ks.transmittance, ratio_r=ks.ratio_r,
                  params_json=np.array(json.dumps(ks.params)))
    for key in ("size_px", "distance_mm", "method", "pupil_samples", "precision", "field_phases"):
        arrays[key] = np.array(ks.params[key])
    for key, value in ks.params["lens"].items():
        arrays[key] = np.float64(value)
    banding = ks.field_kernels is not None and getattr(display, "periodic", True)
    if ks.field_kernels is not None:
        arrays.update(field_kernels=ks.field_kernels, field_power=ks.field_power, field_shifts_um=ks.field_shifts_um)
        z = lens.image_distance_um
        arrays["field_positions_um"] = ks.field_shifts_um * z / (args.distance_mm * 1000)
    if banding:
        profiles = {}
        for axis in ("x", "y"):
            powers = []
            for w in ks.wavelengths_nm:
                x, p = banding_profile(display, lens, float(w), args.distance_mm, axis=axis)
                profiles[(axis, f"{w:.0f} nm")] = (x, p)
                powers.append(p)
            arrays[f"banding_{axis}_um"], arrays[f"banding_{axis}_power"] = x, np.stack(powers)
        period = tuple(z * p / (args.distance_mm * 1000) for p in display.period_um)
        arrays["banding_period_um"] = np.array(period)
        plot_banding(profiles, period, out / "banding.png")
    save_npz(out / "psf.npz", **arrays)
    save_json(out / "psf.json", {**ks.params, "energy_outside": ks.energy_outside, "transmittance": ks.transmittance,
                                 "ratio_r": ks.ratio_r, "notes": ks.notes, "from_cache": hit})
    names = ks.params.get("channels") or [f"{w:g}nm".replace(".", "p") for w in ks.wavelengths_nm]
    save_exr(out / "psf.exr", {f"psf_{n}": k for n, k in zip(names, ks.kernels)})
    plot_kernels(ks, out / "psf.png")
    plot_mtf(ks, out / "mtf.png")

    print(f"{'kernel':>18} {'r (paper)':>10} {'energy outside':>15} {'transmittance':>14}")
    labels = ks.params.get("channels") or [f"{w:g} nm" for w in ks.wavelengths_nm]
    for lab, r, e, t in zip(labels, ks.ratio_r, ks.energy_outside, ks.transmittance):
        print(f"{lab:>18} {r:>10.3f} {e:>15.4%} {t:>14.4f}")
    for note in ks.notes:
        print(f"note: {note}")
    print(f"wrote {out / 'psf.npz'}, psf.exr, psf.png, mtf.png{', banding.png' if banding else ''}"
          f"{' (kernels from cache)' if hit else ''}")
    return 0


def run_study(args) -> int:
    if args.what == "capture":
        from .study_capture import run_study as study_capture
        study_capture(args.out, quick=args.quick)
        print(f"wrote {args.out}/study_capture.csv, study_capture.md, study_capture.png")
        return 0
    if args.what == "render":
        from .study_render import run_study as study_render
        study_render(args.out, quick=args.quick)
        print(f"wrote {args.out}/study_render.csv, study_render.md, study_render.png")
        return 0
    from .study_psf import run_study as study
    study(args.out, quick=args.quick)
    print(f"wrote {args.out}/study_psf.csv, study_psf.md, study_psf.png")
    return 0


def scene_from_args(args):
    """The scene file with the command line's overrides applied."""
    from dataclasses import replace
    from udc_render.scene import Monitor, load_scene, parse_bands
    scene = load_scene(args.scene)
    if args.spp is not None:
        scene = scene.with_render(spp=args.spp, noise=None)
    if args.noise is not None:
        scene = scene.with_render(spp=None, noise=args.noise)
    if args.seed is not None:
        if not 0 <= args.seed < 2**32:
            raise UserError(f"--seed = {args.seed}: expected 0 <= seed < 2^32")
        scene = scene.with_render(seed=args.seed)
    if args.path is not None:
        if args.path == "rgb_matrix" and not isinstance(scene.content, Monitor):
            raise UserError(f"--path rgb_matrix: only for the monitor alone; {scene.source} has {scene.content_type} content")
        scene = scene.with_render(path=args.path)
    if args.bands_nm is not None:
        scene = scene.with_bands(parse_bands(args.bands_nm))
    if args.image is not None:
        if not isinstance(scene.content, Monitor):
            raise UserError(f"--image: only for monitor scenes; {scene.source} has {scene.content_type} content")
        scene = replace(scene, content=replace(scene.content, image=args.image))
    if args.sensor_px is not None:
        w, h = args.sensor_px
        if w != int(w) or h != int(h):
            raise UserError(f"--sensor-px = {w:g},{h:g}: expected whole numbers of pixels")
        scene = replace(scene, sensor=replace(scene.sensor, width_px=int(w), height_px=int(h)))
    if args.pitch_um is not None:
        scene = replace(scene, sensor=replace(scene.sensor, pitch_um=args.pitch_um))
    return scene


def run_render(args) -> int:
    from udc_render.band_io import save_band_image
    from udc_render.render import RenderError, render_scene
    scene = scene_from_args(args)
    try:
        band_image = render_scene(scene, progress=not args.quiet)
    except RenderError as e:
        raise UserError(str(e)) from None
    written = save_band_image(band_image, args.out)
    m = band_image.meta
    noise = f", relative noise {m['noise_rel']:.2e}" if m["noise_rel"] is not None else ""
    print(f"rendered {scene.source} via {m['render_path']} ({m['variant']}): {band_image.bands.shape[0]} bands, "
          f"{band_image.bands.shape[2]}x{band_image.bands.shape[1]} px (margin {band_image.margin_px}), "
          f"{m['spp']} spp{noise}, {m['seconds']:.1f} s")
    print("wrote " + ", ".join(written.values()))
    return 0


def main(argv=None) -> int:
    try:
        parser = build_parser()
        args = parser.parse_args(argv)
        return parser.runners[args.command](args)
    except (UserError, *USER_ERRORS) as exc:
        print(f"udc-render: error: {str(exc).splitlines()[0]}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("udc-render: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
