"""`udc-render evaluate --data DIR --model {input,dep,dep_exact,CHECKPOINT} --out DIR`: score a restorer."""
from __future__ import annotations

from pathlib import Path

from udc_render.cli.args import add_display_argument, out_dir, positive
from udc_render.cli.train import set_threads


def register(sub) -> None:
    e = sub.add_parser("evaluate", help="score a restorer on a dataset split: PSNR, SSIM, LPIPS, MACs, ms/MP")
    e.add_argument("--data", type=Path, required=True, help="a folder written by `udc-render dataset`")
    e.add_argument("--model", required=True,
                   help="input (the degraded capture), dep (DeP with the paper's computed PSF, as the paper ran it), "
                        "dep_exact (DeP with the camera-weighted exact kernels), or a model.pt/checkpoint.pt")
    e.add_argument("--out", type=Path, required=True, help="results folder (rows of several runs are merged)")
    e.add_argument("--split", default="test", choices=("train", "val", "test"),
                   help="the dataset split to score: train, val (validation) or test [test]")
    add_display_argument(e, "the displays to score, by their names in the dataset (a file: the name it gives; any "
                            "other word: a display name of the dataset; `udc-render fit`'s folder: its display.toml). "
                            "A model that needs the panel's description gets it computed from the preset, display "
                            "file or fit folder given here", several=True,
                         unset="a checkpoint's own; all of the dataset's for input and DeP")
    e.add_argument("--image-prefix", help="score only the items whose image starts with this, e.g. builtin: "
                                          "(the scikit-image photographs) or pattern:dead_leaves [all]")
    e.add_argument("--name", help="row name in the tables [input, dep, dep_exact, or the model type]")
    e.add_argument("--denoiser", help="DeP's denoiser [restore.dep's default]")
    e.add_argument("--kernel-px", type=positive("--kernel-px", int),
                   help="DeP's kernel size at the packed-plane pitch, odd [half the synthesis kernel: 257]")
    e.add_argument("--previews", type=int, default=4, help="side-by-side previews per display [4]")
    e.add_argument("--device", default="auto", help="auto, cpu, cuda [auto]")
    e.add_argument("--threads", type=positive("--threads", int), help="CPU threads for torch")
    e.add_argument("--quiet", action="store_true", help="no progress bar")
    e.set_defaults(run=run)


def run(args) -> int:
    out_dir(args.out)
    from restore.evaluate import EvalSettings, evaluate
    from udc_render.optics.displays import display_name
    set_threads(args.threads)
    specs = tuple(t.strip() for t in args.display.split(",") if t.strip()) if args.display else ()
    displays = tuple(display_name(str(Path(t) / "display.toml") if Path(t).is_dir() else t) for t in specs)
    settings = EvalSettings(split=args.split, displays=displays or None, display_specs=specs or None,
                            name=args.name, device=args.device, previews=args.previews, denoiser=args.denoiser,
                            kernel_px=args.kernel_px, image_prefix=args.image_prefix)
    entry = evaluate(args.data, args.model, args.out, settings, progress=not args.quiet)
    for d, r in entry["displays"].items():
        print(f"{entry['name']} {d}: paper protocol PSNR {r['psnr_db_paper']:.2f} dB, SSIM {r['ssim_paper']:.4f}; "
              f"srgb protocol PSNR {r['psnr_db_srgb']:.2f} dB, SSIM {r['ssim_srgb']:.4f}, LPIPS {r['lpips_srgb']:.4f}; "
              f"{r['ms_per_mp']:.0f} ms/MP over {r['images']} images")
    print(f"tables: {args.out / 'results.md'}, {args.out / 'results.csv'}")
    return 0
