"""The calibration's outputs: the checks as a text table and one PNG per protocol (γ, noise, PSF, MTF)."""
from __future__ import annotations

from pathlib import Path

import numpy as np

from udc_render.calibration.rig import CHANNELS
from udc_render.io.plots import pyplot, save_plot


def format_table(checks: list) -> str:
    """The checks as fixed-width text: quantity, recovered, truth, error, tolerance, pass / FAIL."""
    lines = [f"{'quantity':<34} {'recovered':>11} {'truth':>11} {'error':>8} {'tolerance':>9}  result"]
    for c in checks:
        truth = "" if c["truth"] is None else f"{c['truth']:.4g}"
        err = "" if c["error"] is None else f"{c['error']:.2%}"
        tol = c["tolerance"] if isinstance(c["tolerance"], str) else (
            f"{c['tolerance']:.2%}" if c["tolerance"] < 1 else f"{c['tolerance']:.3g}")
        lines.append(f"{c['quantity']:<34} {c['recovered']:>11.4g} {truth:>11} {err:>8} {tol:>9}  "
                     f"{'pass' if c['pass'] else 'FAIL'}")
    return "\n".join(lines)


def plot_gamma(g: dict, path: Path) -> None:
    """Per channel: display mean against glass mean per level, the fitted and the true γ lines."""
    fig, axes = pyplot().subplots(1, 4, figsize=(16, 3.8))
    for k, ax in enumerate(axes):
        x, y = np.asarray(g["glass_mean_w"])[:, k], np.asarray(g["display_mean_w"])[:, k]
        used = np.asarray(g["used"])[:, k]
        ax.plot(x[used], y[used], "o", ms=3, label="levels used")
        ax.plot(x[~used], y[~used], "x", ms=4, label="levels touching a clip")
        ax.plot(x, g["gamma"][k] * x, "-", label=f"fit γ = {g['gamma'][k]:.4f}")
        ax.plot(x, g["truth"][k] * x, "--", label=f"truth {g['truth'][k]:.4f}")
        ax.set(title=f"γ {CHANNELS[k]}", xlabel="glass mean (w)", ylabel="display mean (w)")
        ax.legend(fontsize=7)
    save_plot(fig, path)


def plot_noise(n: dict, path: Path) -> None:
    """Per channel: binned variance against intensity w, the fitted and the true λ_read + λ_shot · w."""
    fig, axes = pyplot().subplots(1, 4, figsize=(16, 3.8))
    for k, (ax, f) in enumerate(zip(axes, n["fits"])):
        w, v = np.asarray(f["w"]), np.asarray(f["var"])
        ax.plot(w, v, "o", ms=3, label="bins (clear of the clips)")
        ax.plot(w, f["lambda_read"] + f["lambda_shot"] * w, "-", label="fit")
        ax.plot(w, n["truth_read"][k] + n["truth_shot"][k] * w, "--", label="truth")
        ax.set(title=f"noise {CHANNELS[k]}", xlabel="intensity w", ylabel="variance (w²)")
        ax.legend(fontsize=7)
    save_plot(fig, path)


def plot_psf(p: dict, path: Path) -> None:
    """Recovered and configured PSF (log10, relative to the peak) and their central rows."""
    fig, axes = pyplot().subplots(1, 3, figsize=(15, 4))
    wx, wy = p["window_um"]
    ext = (-wx / 2, wx / 2, wy / 2, -wy / 2)
    for ax, key in zip(axes[:2], ("recovered", "configured")):
        a = np.asarray(p[key])
        im = ax.imshow(np.log10(np.maximum(a / a.max(), 1e-5)), extent=ext, cmap="magma", vmin=-5, vmax=0)
        ax.set(title=f"{key} PSF, {p['wavelength_nm']:g} nm (log10)", xlabel="x (µm)", ylabel="y (µm)")
    fig.colorbar(im, ax=axes[1], fraction=0.046)
    rec, conf = np.asarray(p["recovered"]), np.asarray(p["configured"])
    xs = np.linspace(-wx / 2, wx / 2, rec.shape[1])
    axes[2].semilogy(xs, np.maximum(rec[rec.shape[0] // 2], 1e-9), label="recovered")
    axes[2].semilogy(xs, np.maximum(conf[conf.shape[0] // 2], 1e-9), "--", label="configured")
    axes[2].set(title=f"central row, NCC {p['ncc']:.4f}", xlabel="x (µm)")
    axes[2].legend()
    save_plot(fig, path)


def plot_mtf(m: dict, display: str, path: Path) -> None:
    """Modulation of the G channels along x and y: glass, `display` and their ratio."""
    fig, axes = pyplot().subplots(1, 2, figsize=(12, 4))
    for ax, axis in zip(axes, ("x", "y")):
        f, r = np.asarray(m["frequencies"]), m[axis]
        ax.plot(f, np.asarray(r["glass"])[:, 1:3].mean(1), "o-", label="glass (G)")
        ax.plot(f, np.asarray(r["display"])[:, 1:3].mean(1), "s-", label=f"{display} (G)")
        ax.plot(f, r["relative_G"], "^--", label=f"{display} / glass (G)")
        ax.set(title=f"MTF along {axis}", xlabel="cycles / pixel (1.55 µm)", ylabel="modulation", xscale="log",
               ylim=(0, 1.05))
        ax.legend(fontsize=8)
    save_plot(fig, path)


def plot_all(result: dict, out: Path) -> list[str]:
    """gamma.png, noise.png (when the noise was calibrated), psf.png and mtf.png in out; their names."""
    plot_gamma(result["gamma"], out / "gamma.png")
    written = ["gamma.png"]
    if "fits" in result["noise"]:
        plot_noise(result["noise"], out / "noise.png")
        written.append("noise.png")
    plot_psf(result["psf"], out / "psf.png")
    plot_mtf(result["mtf"], result["display"], out / "mtf.png")
    return written + ["psf.png", "mtf.png"]
