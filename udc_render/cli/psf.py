"""`udc-render psf`: wave-optics kernels of a display in front of the lens, written as files.

    udc-render psf --display {glass,none,toled,poled,FILE.toml,IMAGE} --wavelengths-nm 450,520,640 --out DIR
"""
from __future__ import annotations

import argparse
import math
import sys
import warnings
from pathlib import Path

from tqdm import tqdm

from psf.engine import DEFAULT_FIELD_PHASES, METHODS, PAPER_SENSOR_UM, PRECISIONS, AliasingWarning, UnderSamplingWarning
from psf.pupil import MASK_RASTERS
from udc_render.cli.args import (
    UserError,
    add_display_argument,
    float_list,
    float_pair,
    non_negative,
    odd_size,
    out_dir,
    positive,
)
from udc_render.io.kernels import write_kernel_files


def _bands(text):
    try:
        bands = [tuple(float(v) for v in b.split("-")) for b in text.split(",") if b.strip()]
    except ValueError:
        raise argparse.ArgumentTypeError(f"--bands-nm must look like 400-500,500-600, got '{text}'") from None
    if not bands or any(len(b) != 2 or not 0 < b[0] < b[1] for b in bands):
        raise argparse.ArgumentTypeError(f"--bands-nm must look like 400-500,500-600 with lo < hi, got '{text}'")
    return bands


def _zernike_term(text):
    """--zernike N,M,WAVES: one Zernike term of the lens (psf.zernike; checked with the others by psf.Lens)."""
    parts = text.split(",")
    try:
        n, m, a = int(parts[0]), int(parts[1]), float(parts[2])
        if len(parts) != 3 or not math.isfinite(a):
            raise ValueError
    except (ValueError, IndexError):
        raise argparse.ArgumentTypeError(f"--zernike must look like N,M,WAVES (e.g. 4,0,0.05: 0.05 waves RMS of "
                                         f"spherical aberration), got '{text}'") from None
    return n, m, a


def register(sub) -> None:
    p = sub.add_parser("psf", help="wave-optics PSF kernels of a display in front of a lens")
    p.set_defaults(run=run)
    add_display_argument(p, "the display whose layout is in front of the lens (glass and none: the bare lens; a "
                            "display file's transmission and gain do not enter the kernels)", default="toled",
                         micrograph="pixels of --micrograph-pixel-um, values as --micrograph-values, tiles turned "
                                    "by --tile-rotation")
    spec = p.add_mutually_exclusive_group()
    spec.add_argument("--wavelengths-nm", type=float_list, default=[450.0, 520.0, 640.0],
                      help="monochromatic kernels at these wavelengths [450,520,640]")
    spec.add_argument("--bands-nm", type=_bands, help="band kernels, e.g. 400-500,500-600,600-700")
    spec.add_argument("--camera", help="channel-effective kernels for a colour-science camera "
                                       "('Nikon 5100 (NPL)', 'Sigma SDMerill (NPL)') or a CSV of sensitivities")
    p.add_argument("--band-step-nm", type=positive("--band-step-nm"), default=None,
                   help="wavelength step inside a band or channel [auto: λ_lo / size, 1.6 nm at 400 nm, 255 px]")
    p.add_argument("--weight", default="E",
                   help="weight spectrum for --bands-nm and --camera: E (flat), a colour-science illuminant "
                        "such as D65, or a CSV (wavelength_nm, weight) [E]")
    p.add_argument("--distance-mm", type=non_negative("--distance-mm"),
                   help="display-to-lens distance d; 0 = principal-plane model; given, it wins over a display "
                        "file's distance_mm [a display file's distance_mm, else 0]")
    p.add_argument("--pitch-um", "--pixel-um", dest="pitch_um", type=positive("--pitch-um"), default=3.1,
                   help="sensor pixel pitch (old spelling --pixel-um) [3.1]")
    p.add_argument("--kernel-px", "--size", dest="kernel_px", type=odd_size("--kernel-px"), default=255,
                   help="kernel size in pixels, odd (old spelling --size) [255]")
    p.add_argument("--focal-length-um", type=positive("--focal-length-um"), default=6000.0,
                   help="focal length f of the lens in µm [6000, the paper's]")
    p.add_argument("--aperture-um", type=positive("--aperture-um"), default=3333.0,
                   help="aperture diameter D in µm [3333: f/1.8]")
    p.add_argument("--focus-distance-mm", type=positive("--focus-distance-mm"), default=math.inf,
                   help="distance the lens is focused at; the sensor sits at its image [inf]")
    p.add_argument("--object-distance-mm", type=positive("--object-distance-mm"), default=math.inf,
                   help="distance of the object; away from the focus distance the kernels are defocused "
                        "(paraxial pupil phase) [inf]")
    p.add_argument("--zernike", type=_zernike_term, action="append", metavar="N,M,WAVES",
                   help="a wavefront aberration of the lens: the OSA/ANSI Zernike term Z(N, M) with WAVES RMS at "
                        "550 nm, e.g. 4,0,0.05 (spherical), 3,1,0.05 (coma along x), 2,2,0.05 (astigmatism); repeat "
                        "for several; the same optical path at every wavelength (psf/zernike.py) [none: "
                        "diffraction-limited]")
    p.add_argument("--method", choices=METHODS, default="mft",
                   help="Fraunhofer transform to the pixels: mft: matrix Fourier transform of the pupil's "
                        "autocorrelation, exact pixel integration at any pitch (default); czt: the same sum by "
                        "chirp-z; paper: the paper's recipe as printed (2× padded DFT intensity, cubic "
                        "down-sampling by its printed r: 2.41, 2.98, 3.44 at 640, 520, 450 nm; psf/paper.py) [mft]")
    p.add_argument("--pupil-samples", type=positive("--pupil-samples", int), default=None,
                   help="samples across the aperture [auto: ≥ 1024 and alias-free]")
    p.add_argument("--field-phases", type=positive("--field-phases", int), default=None,
                   help="mask shifts per axis over one display period, d > 0 only [4]")
    p.add_argument("--sensor-extent-um", "--sensor-um", dest="sensor_extent_um",
                   type=float_pair("--sensor-extent-um"), default=PAPER_SENSOR_UM,
                   help="image width,height in µm: field phases span what it sees of a banding period "
                        "(old spelling --sensor-um) [3174.4,1587.2, the paper's 2048×1024 × 1.55 µm]")
    p.add_argument("--precision", choices=tuple(PRECISIONS), default="float32",
                   help="float32: complex64 FFTs and products (default); float64: complex128 [float32]")
    p.add_argument("--mask-raster", choices=MASK_RASTERS, default="band_limited",
                   help="how the display's mask is sampled on the pupil grid: band_limited: its exact Fourier "
                        "series cut at the grid's band, nothing aliases (default); area: area-weighted cell "
                        "averages, then de-apodised [band_limited]")
    p.add_argument("--micrograph-pixel-um", type=positive("--micrograph-pixel-um"), default=1.0,
                   help="pixel size of a micrograph display in µm [1.0]")
    p.add_argument("--micrograph-values", choices=("amplitude", "intensity"), default="amplitude",
                   help="what a micrograph image's pixels are: amplitude: the amplitude transmission (default); "
                        "intensity: the power transmission (its square root is taken) [amplitude]")
    p.add_argument("--tile-rotation", action="store_true", help="rotate each micrograph tile randomly")
    p.add_argument("--tile-flip", action="store_true",
                   help="with --tile-rotation, also mirror each micrograph tile at random (the 8 elements of D4)")
    p.add_argument("--tile-seed", "--seed", dest="tile_seed", type=int, default=0,
                   help="seed of the tile rotations (old spelling --seed) [0]")
    p.add_argument("--no-cache", action="store_true", help="neither read nor write the kernel cache")
    p.add_argument("--cache-dir", type=Path, help="kernel cache folder [$UDC_RENDER_CACHE or ~/.cache/udc-render/psf]")
    p.add_argument("--out", type=Path, default=Path("out/psf"), help="output folder [out/psf]")


def layout_and_distance(args):
    """The --display's psf layout (None: the bare lens) and the distance d: --distance-mm when given,
    else the display's own (a display file's distance_mm; 0 for the presets and micrographs)."""
    from udc_render.optics.displays import load_display
    display = load_display(args.display, pixel_um=args.micrograph_pixel_um, values=args.micrograph_values,
                           random_rotation=args.tile_rotation, seed=args.tile_seed, flip=args.tile_flip)
    return display.layout, display.distance_mm if args.distance_mm is None else args.distance_mm


def compute(args, display, lens, bar):
    """(KernelSet, from_cache) for the kind of kernels asked: bands, camera channels or wavelengths;
    args.distance_mm is the resolved distance (layout_and_distance)."""
    from psf import compute_kernels
    from psf.cache import cached
    from psf.spectral import auto_step_nm, band_kernels, channel_kernels, load_weight
    common = dict(pixel_um=args.pitch_um, size_px=args.kernel_px, distance_mm=args.distance_mm,
                  field_phases=args.field_phases, method=args.method, pupil_samples=args.pupil_samples,
                  precision=args.precision, mask_raster=args.mask_raster, sensor_um=args.sensor_extent_um,
                  progress=bar.update, cache_dir=args.cache_dir)
    phases = (args.field_phases or DEFAULT_FIELD_PHASES) ** 2 if args.distance_mm > 0 and display is not None else 1
    if args.bands_nm:
        bar.total = phases * sum(math.ceil((hi - lo) / (args.band_step_nm or auto_step_nm(lo, args.kernel_px)) - 1e-9)
                                 for lo, hi in args.bands_nm)
        return cached(band_kernels, "band", display, lens, not args.no_cache, bands_nm=args.bands_nm,
                      step_nm=args.band_step_nm, weight=load_weight(args.weight), weight_name=args.weight, **common)
    if args.camera:
        return cached(channel_kernels, "channel", display, lens, not args.no_cache, camera=args.camera,
                      illuminant=args.weight, step_nm=args.band_step_nm, **common)
    bar.total = phases * len(args.wavelengths_nm)
    return cached(compute_kernels, "mono", display, lens, not args.no_cache, wavelengths_nm=args.wavelengths_nm,
                  **common)


def run(args) -> int:
    from psf import Lens
    display, args.distance_mm = layout_and_distance(args)  # a bad display refused before the folder is made
    out = out_dir(args.out)
    lens = Lens(args.focal_length_um, args.aperture_um, args.focus_distance_mm, args.object_distance_mm,
                tuple(args.zernike or ()))
    with warnings.catch_warnings(record=True) as caught, tqdm(desc="psf kernels", unit="kernel", disable=None) as bar:
        warnings.simplefilter("always", AliasingWarning)
        warnings.simplefilter("always", UnderSamplingWarning)
        ks, hit = compute(args, display, lens, bar)
    for w in caught:
        if issubclass(w.category, AliasingWarning) and args.pupil_samples is not None:
            raise UserError(f"--pupil-samples is too coarse for the requested window: {w.message}")
    for w in {str(w.message) for w in caught}:
        print(f"warning: {w}", file=sys.stderr)
    written = write_kernel_files(out, ks, display, lens, args.distance_mm, hit)
    print(f"{'kernel':>18} {'r (paper)':>10} {'energy outside':>15} {'transmittance':>14}")
    labels = ks.params.get("channels") or [f"{w:g} nm" for w in ks.wavelengths_nm]
    for lab, r, e, t in zip(labels, ks.ratio_r, ks.energy_outside, ks.transmittance):
        print(f"{lab:>18} {r:>10.3f} {e:>15.4%} {t:>14.4f}")
    for note in ks.notes:
        print(f"note: {note}")
    print(f"wrote {out / written[0]}, {', '.join(written[1:])}{' (kernels from cache)' if hit else ''}")
    return 0
