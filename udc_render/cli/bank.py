"""`udc-render bank`: a kernel bank for the online degradation (`udc-render train --degrade online --bank DIR`).

    udc-render bank --display toled,poled --out DIR [--profile physical|paper] [--kernel-px S] [--scene monitor]
    udc-render bank --randomize default|FILE.toml --panels N [--randomize-seed S] --out DIR

Each panel: the per-channel kernels at the sensor pitch (d > 0: with the rank-r field bases), γ, the sensor
(noise model, gain, exposure, defect pixels, fixed-pattern noise) and, in the physical profile, the far field
and the display's haze; its record's "effects" list what it applies. udc_render/dataset/bank.py has the format.
"""
from __future__ import annotations

from pathlib import Path

from udc_render.cli.args import (
    UserError,
    add_channel_kernels_argument,
    add_display_argument,
    capture_setup,
    field_rank,
    float_pair,
    non_negative,
    odd_size,
    out_dir,
    positive,
)
from udc_render.scene import load_scene
from udc_render.scene.geometry import sensor_kernel_px
from udc_render.scene.overrides import with_overrides

DEFAULT_DISPLAYS = "toled,poled"


def register(sub) -> None:
    from udc_render.profiles import DEFAULT_PROFILE, PHYSICAL_DISTANCE_MM, PROFILES
    p = sub.add_parser("bank", help="a kernel bank: each panel's per-channel kernels (and field bases where d > 0), "
                                    "γ and sensor, for `udc-render train --degrade online`")
    add_display_argument(p, "the bank's panels (repeat the option or separate by commas)", several=True,
                         action="append", unset=DEFAULT_DISPLAYS)
    p.add_argument("--randomize", metavar="default|FILE.toml",
                   help="drawn panels instead of --display (docs/guides/randomize.md): 'default', the documented "
                        "ranges, or a TOML file of distributions; panel i has the display and lens of draw_panel i "
                        "and the sensor, exposure and brightness of capture draw i")
    p.add_argument("--panels", type=positive("--panels", int), help="with --randomize: the number of panels [8]")
    p.add_argument("--randomize-seed", type=int, default=0, help="with --randomize: the seed of every draw [0]")
    p.add_argument("--out", type=Path, required=True, help="the bank's folder (re-run the same command to finish it)")
    p.add_argument("--scene", default="monitor", help="the scene whose sensor, lens and bands the kernels are made "
                                                      "for (a scene file or a built-in name) [monitor]")
    p.add_argument("--sensor-px", type=float_pair("--sensor-px"),
                   help="sensor width,height in pixels: the frame the field (d > 0) is laid on [the scene's]")
    p.add_argument("--pitch-um", type=positive("--pitch-um"), help="sensor pixel pitch in µm [the scene's]")
    p.add_argument("--bands-nm", help="LOW:HIGH:STEP in nm: γ of display files, the far field, the d > 0 kernels' "
                                      "λ step [the scene's]")
    p.add_argument("--kernel-px", type=odd_size("--kernel-px"),
                   help="kernel size at the sensor pitch, odd (a crop needs half of it as margin on every side) "
                        "[the scene's: 2 · ceil(render.margin_um / pitch) + 1, 513 for the default scene]")
    p.add_argument("--profile", choices=tuple(PROFILES), default=DEFAULT_PROFILE,
                   help=f"paper: its channel kernels at d = 0, Gaussian noise, no defects, FPN, far field or haze; "
                        f"physical: the camera's channel kernels, d = {PHYSICAL_DISTANCE_MM:g} mm for the presets "
                        f"(field bases), Poisson noise, defect pixels, FPN, the far field, the display's haze "
                        f"(udc_render/profiles.py) [{DEFAULT_PROFILE}]")
    p.add_argument("--distance-mm", type=non_negative("--distance-mm"),
                   help="display-to-lens distance d of every display [the profile's for the presets, a file's own]")
    add_channel_kernels_argument(p)
    p.add_argument("--field-phases", type=positive("--field-phases", int), help="d > 0: phases per axis [4]")
    p.add_argument("--field-rank", type=field_rank, default=4,
                   help="d > 0: the rank of each channel's basis of phase kernels, or 'exact' (every phase) [4]")
    p.add_argument("--sensor-config", type=Path, help="TOML file of sensor-model keys (udc_render/sensor/config.py)")
    p.add_argument("--noise-model", choices=("poisson", "gaussian", "none"),
                   help="sensor noise (udc_render/sensor/noise.py): poisson: Poisson shot plus Gaussian read noise; "
                        "gaussian: its heteroscedastic Gaussian approximation; none: the noise-free signal, quantised "
                        "[the profile's: gaussian for paper; else the sensor config's, poisson]")
    p.add_argument("--exposure-s", type=positive("--exposure-s"),
                   help="exposure time (hot pixels' and dark current's charge) [auto: the monitor's white at 0.8 of "
                        "the full well through glass, as the synthesis]")
    p.add_argument("--no-cache", action="store_true", help="neither read nor write the kernel cache")
    p.add_argument("--cache-dir", type=Path, help="kernel cache folder [$UDC_RENDER_CACHE or ~/.cache/udc-render/psf]")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.set_defaults(run=run)


def _scene(args):
    return with_overrides(load_scene(args.scene), bands_nm=args.bands_nm, sensor_px=args.sensor_px,
                          pitch_um=args.pitch_um)


def _kernel_px(args, scene) -> int:
    if args.kernel_px is not None:
        return args.kernel_px
    return sensor_kernel_px(scene)


def run(args) -> int:
    from udc_render.dataset.bank_make import bank_settings, make_bank, preset_specs, random_specs
    from udc_render.profiles import describe
    if args.randomize is None and (args.panels is not None or args.randomize_seed != 0):
        raise UserError("--panels and --randomize-seed go with --randomize (drawn panels)")
    if args.randomize is not None and args.display is not None:
        raise UserError("--display with --randomize: the panels are drawn; give one of them")
    displays = ",".join(args.display) if args.display else DEFAULT_DISPLAYS
    out_dir(args.out)
    scene = _scene(args)
    distance, args.distance_mm = args.distance_mm, None  # applied below: the bank has no --form to refuse it
    cfg, loaded = capture_setup(args, displays if args.randomize is None else "glass")
    asked = [t.strip() for t in displays.split(",")]
    loaded = [d for d in loaded if not d.is_glass or {"glass", "none"} & set(asked)]  # glass only when named
    if distance is not None:
        loaded = [d if d.is_glass else d.with_distance(distance) for d in loaded]
    kernel_px = _kernel_px(args, scene)
    extra = {"profile": describe(cfg.profile), "distance_mm_option": distance}
    if args.randomize is None:
        specs = preset_specs(loaded, scene, cfg)
    else:
        from udc_render.dataset.randomize import load_distributions
        dists = load_distributions(args.randomize)
        n = args.panels or 8
        if distance is not None:
            raise UserError("--distance-mm with --randomize: the panels' d is drawn (display.distance_mm)")
        specs = random_specs(dists, n, args.randomize_seed, scene, cfg)
        extra.update(randomize=dists.describe(), randomize_seed=args.randomize_seed, panels=n)
    s = make_bank(args.out, specs, bank_settings(scene, cfg, kernel_px, specs, extra), kernel_px,
                  progress=not args.quiet)
    field = f"; field bases (d > 0): {', '.join(s['field_panels'])}" if s["field_panels"] else ""
    print(f"bank of {s['panels']} panels ({', '.join(s['names'])}; {s['made']} made now) in {args.out}: kernels "
          f"{kernel_px} px at {scene.sensor.pitch_um:g} µm{field}")
    return 0
