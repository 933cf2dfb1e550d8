"""`udc-render render SCENE --out DIR`: the band render alone (render.exr, render.json, previews)."""
from __future__ import annotations

from pathlib import Path

from udc_render.cli.args import add_scene_arguments, out_dir, scene_from_args
from udc_render.io.band_image import save_band_image


def register(sub) -> None:
    r = sub.add_parser("render", help="render a scene to band radiance images with Mitsuba 3")
    r.set_defaults(run=run)
    r.add_argument("--out", type=Path, default=Path("out/render"), help="output folder [out/render]")
    add_scene_arguments(r)


def run(args) -> int:
    from udc_render.render import render_scene
    scene = scene_from_args(args)
    out = out_dir(args.out)
    band_image = render_scene(scene, progress=not args.quiet)
    written = save_band_image(band_image, out)
    m = band_image.meta
    noise = f", relative noise {m['noise_rel']:.2e}" if m["noise_rel"] is not None else ""
    print(f"rendered {scene.source} via {m['render_path']} ({m['variant'] or m['backend']}): "
          f"{band_image.bands.shape[0]} bands, "
          f"{band_image.bands.shape[2]}x{band_image.bands.shape[1]} px (margin {band_image.margin_px}), "
          f"{m['spp']} spp{noise}, {m['seconds']:.1f} s")
    print("wrote " + ", ".join(written.values()))
    return 0
