"""Where in spatial frequency a restorer's error lies: its mean squared error split into octave bands.

By Parseval, mean((y − x)²) = Σ_f |FFT(y − x)(f)|² / N² over a frame of N pixels, so the error splits
exactly into radial bands of spatial frequency |f| (cycles per sensor pixel; OCTAVE_EDGES): the bands
sum to the MSE. Beside them, the display's transfer in each band: the mean |OTF| of its known green
kernel (restore.known, at the packed pitch, so defined up to 1/4 cycle per sensor pixel).

Per display: the split's first `items` pairs, cropped to the central `crop_px` square (the validation
crop of restore.train), clipped to [0, 1] like the PSNR. Methods are the restorers of restore.evaluate
('input', 'dep', 'dep_exact', or a checkpoint path).

    python -m restore.studies.error_bands DATA --display toled --method input --method PATH [...]
        [--split val] [--items 6] [--crop-px 512] [--out out/error_bands]

prints a Markdown table (MSE per band, and each method's share of the total) and writes
<out>/error_bands_<display>.png.
"""
from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

from restore.studies.options import parse_options
from udc_render.errors import UdcError
from udc_render.io.files import save_figure
from udc_render.io.plots import pyplot

OCTAVE_EDGES = (0.0, 1 / 64, 1 / 32, 1 / 16, 1 / 8, 1 / 4, 1 / 2, 2 ** -0.5)  # cycles / px; the last: the corner


def radial_frequency(h: int, w: int) -> np.ndarray:
    """[h, w] |f| in cycles per pixel on numpy's FFT grid."""
    return np.hypot(np.fft.fftfreq(h)[:, None], np.fft.fftfreq(w)[None])


def band_mse(err: np.ndarray, edges=OCTAVE_EDGES) -> np.ndarray:
    """[bands] the MSE of err [C, H, W] carried by each radial band [edges[i], edges[i+1]); sums to
    mean(err²) (Parseval) when the last edge reaches the corner, √2 / 2."""
    err = np.asarray(err, np.float64)
    power = np.abs(np.fft.fft2(err, axes=(-2, -1))) ** 2 / err[0].size ** 2 / err.shape[0]
    r = radial_frequency(*err.shape[-2:])
    return np.array([power[..., (r >= a) & (r < b) | ((b == edges[-1]) & (r >= b))].sum()
                     for a, b in zip(edges[:-1], edges[1:])])


def band_transfer(kernel: np.ndarray, pitch_ratio: int = 2, edges=OCTAVE_EDGES, size_px: int = 256) -> np.ndarray:
    """[bands] mean |OTF| of a unit-sum kernel [k, k] sampled every `pitch_ratio` sensor pixels, per band
    of sensor frequency; NaN where the band lies above its Nyquist limit (1 / (2 · pitch_ratio))."""
    k = kernel.shape[-1]
    size_px = max(size_px, 2 * k)
    padded = np.zeros((size_px, size_px))
    padded[:k, :k] = kernel
    otf = np.abs(np.fft.fft2(padded))
    r = radial_frequency(size_px, size_px) / pitch_ratio  # cycles per sensor pixel
    return np.array([otf[(r >= a) & (r < b)].mean() if a < 0.5 / pitch_ratio else np.nan
                     for a, b in zip(edges[:-1], edges[1:])])


def method_bands(data_dir: Path, display: str, methods: dict[str, str], split: str = "val", items: int = 6,
                 crop_px: int = 512) -> dict[str, np.ndarray]:
    """{name: [bands] MSE averaged over the split's first `items` pairs} for methods {name: 'input', 'dep' or a
    checkpoint path} (module doc)."""
    from restore.data import list_pairs, load_pair
    from restore.evaluate import BUILTIN_METHODS, RESTORERS, EvalSettings
    from restore.train import centre_crop
    every = list_pairs(Path(data_dir), split, [display])
    crops = [(p, centre_crop(*load_pair(p), crop_px)) for p in every[:items]]
    out = {}
    for name, method in methods.items():
        restorer = RESTORERS[method if method in BUILTIN_METHODS else "model"](method, EvalSettings(split=split))
        restorer.prepare({display: every})
        out[name] = np.mean([band_mse(np.clip(restorer.restore(packed, p)[0], 0, 1) - np.clip(gt, 0, 1))
                             for p, (packed, gt) in crops], axis=0)
    return out


def display_transfer(data_dir: Path, display: str, split: str = "val") -> np.ndarray:
    """band_transfer of the display's green kernel (restore.known's exact one, the split's first pair)."""
    from restore.data import list_pairs
    from restore.known import known_kernels_rggb
    return band_transfer(known_kernels_rggb(list_pairs(Path(data_dir), split, [display])[0], source="exact")[1])


def weakest_band_text(bands: dict[str, np.ndarray], transfer: np.ndarray, edges=OCTAVE_EDGES) -> str:
    """One sentence: the band the display passes least, and each row's error there as a share of the input's."""
    i = int(np.nanargmin(transfer))
    shares = ", ".join(f"{name} {v[i] / bands['input'][i]:.2f}" for name, v in bands.items() if name != "input")
    return (f"The display passes least in {edges[i]:.3g}–{edges[i + 1]:.3g} cycles/px (mean |OTF| {transfer[i]:.3f}); "
            f"there each row keeps this share of the input's error: {shares}.")


def markdown(bands: dict[str, np.ndarray], transfer: np.ndarray, edges=OCTAVE_EDGES) -> str:
    """Rows: methods (MSE per band, total, PSNR); a last row: the display's mean |OTF| per band."""
    heads = [f"{a:.3g}–{b:.3g}" for a, b in zip(edges[:-1], edges[1:])]
    lines = ["| method | " + " | ".join(heads) + " | MSE | PSNR (dB) |", "|---" * (len(heads) + 3) + "|"]
    for name, v in bands.items():
        lines.append(f"| {name} | " + " | ".join(f"{x:.2e}" for x in v)
                     + f" | {v.sum():.2e} | {-10 * np.log10(v.sum()):.2f} |")
    lines.append("| display mean \\|OTF\\| (green) | "
                 + " | ".join("—" if np.isnan(t) else f"{t:.3f}" for t in transfer) + " | | |")
    return "\n".join(lines)


def plot(bands: dict[str, np.ndarray], transfer: np.ndarray, path: Path, title: str, edges=OCTAVE_EDGES) -> None:
    plt = pyplot()
    centres = np.sqrt(np.maximum(edges[:-1], edges[1] / 2) * np.array(edges[1:]))
    fig, ax = plt.subplots(figsize=(6.4, 4.0))
    for name, v in bands.items():
        ax.loglog(centres, v, "o-", label=name)
    ax.set_xlabel("spatial frequency (cycles / sensor px), octave bands")
    ax.set_ylabel("error power in the band (MSE)")
    twin = ax.twinx()
    twin.semilogx(centres, transfer, "k--", label="display mean |OTF| (green)")
    twin.set_ylim(0, 1.05)
    twin.set_ylabel("display mean |OTF|")
    ax.legend(fontsize=8, loc="lower left")
    twin.legend(fontsize=8, loc="upper right")
    ax.set_title(title, fontsize=10)
    save_figure(fig, path)
    plt.close(fig)


def main(argv: list[str]) -> None:
    usage = "python -m restore.studies.error_bands DATA --display D --method M [--method M ...] [--split val] " \
            "[--items 6] [--crop-px 512] [--out out/error_bands]"
    from restore.evaluate import BUILTIN_METHODS
    pos, o = parse_options(argv, usage, repeated=("method",))
    if len(pos) != 1 or "display" not in o or not o["method"]:
        sys.exit(f"usage: {usage}")
    data, display, split = Path(pos[0]), o["display"], o.get("split", "val")
    items, crop_px, out = int(o.get("items", 6)), int(o.get("crop_px", 512)), Path(o.get("out", "out/error_bands"))
    try:
        out.mkdir(parents=True, exist_ok=True)
        transfer = display_transfer(data, display, split)
        methods = {m if m in BUILTIN_METHODS else Path(m).parent.name: m for m in o["method"]}
        bands = method_bands(data, display, methods, split, items, crop_px)
    except (UdcError, OSError) as exc:
        sys.exit(f"error: {exc}")
    print(markdown(bands, transfer))
    if "input" in bands:
        print("\n" + weakest_band_text(bands, transfer))
    path = out / f"error_bands_{display}.png"
    plot(bands, transfer, path, f"{display}: error by spatial frequency ({split}, {items} items, central {crop_px} px)")
    print(f"wrote {path}")


if __name__ == "__main__":
    main(sys.argv[1:])
