"""What the realism capture rows (udc_render.studies.realism_capture) compare against: the paper's
numbers, the verdicts on ours, and the rows' display labels and default scene.
"""
from __future__ import annotations

from udc_render.optics.displays import PAPER_GAMMA, Display
from udc_render.scene import load_scene
from udc_render.scene.overrides import with_overrides
from udc_render.sensor import rgb_to_rggb

FRAME_PX = (2048, 1024)  # the paper's sensor
GAMMA_TOL = 0.01
PAPER_DEP = {"toled": (28.50, 0.9117), "poled": (16.97, 0.7084)}  # PSNR dB, SSIM (l.380)
PAPER_BANDING = "low to moderate visibility (real data, d > 0, l.498)"
VISIBILITY = ((0.1, "invisible"), (0.5, "low"), (2.0, "moderate"))  # upper bounds; above: "strong"


def paper_gamma_rggb(display: Display) -> tuple | None:
    """The paper's γ (R, Gr, Gb, B) for the display's family (its name: toled, poled), else None."""
    g = PAPER_GAMMA.get(display.name)
    return None if g is None or display.name == "glass" else tuple(rgb_to_rggb(g))


def gamma_verdict(ours: float, paper: float) -> str:
    """'within 1 %' when |ours / paper − 1| < GAMMA_TOL, else '**off by ±x %**'."""
    off = ours / paper - 1.0
    return "within 1 %" if abs(off) < GAMMA_TOL else f"**off by {100 * off:+.1f} %**"


def dep_verdict(ours: float, paper: float, unit: str = "dB") -> str:
    """'at or above the paper (our DeP knows the PSF)', else '**below the paper by x**'."""
    if ours >= paper:
        return "at or above the paper (our DeP knows the PSF)"
    gap = f"{paper - ours:.2f} dB" if unit == "dB" else f"{paper - ours:.4f}"
    return f"**below the paper by {gap}**"


def visibility_verdict(visibility: float) -> str:
    """VISIBILITY's class of V = contrast / per-pixel relative noise (module doc)."""
    for upper, name in VISIBILITY:
        if visibility < upper:
            return name
    return "strong"


def dep_order_row(toled_rows: list[dict], poled_rows: list[dict]) -> dict:
    """The cross-display row: the paper's DeP is 11.5 dB lower on the P-OLED (28.50 vs 16.97 dB); holds
    when our P-OLED DeP PSNR is below our T-OLED's (the rows of capture_rows, key 'dep_psnr_db')."""
    def value(rows):
        return next(r["value"] for r in rows if r.get("key") == "dep_psnr_db")
    t, p = value(toled_rows), value(poled_rows)
    (pt, _), (pp, _) = PAPER_DEP["toled"], PAPER_DEP["poled"]
    return {"display": "toled vs poled", "pitch_um": None, "observable": "DeP PSNR order (paper protocol)",
            "ours": f"T-OLED {t:.2f} dB, P-OLED {p:.2f} dB",
            "paper": f"T-OLED {pt:.2f} dB, P-OLED {pp:.2f} dB (P-OLED harder)",
            "verdict": (f"holds: P-OLED harder ({p - t:+.2f} dB; paper {pp - pt:+.2f} dB)" if p < t
                        else f"**fails**: P-OLED not harder ({p - t:+.2f} dB)"),
            "key": "dep_order", "value": p - t}


def default_scene(sensor_px: tuple[int, int] = FRAME_PX):
    """The default monitor scene (spectral synthesis of udc-render demo) at `sensor_px`."""
    return with_overrides(load_scene("monitor"), sensor_px=sensor_px)


def display_label(display: Display) -> str:
    return display.name if display.distance_mm == 0 else f"{display.name} d={display.distance_mm:g} mm"


def display_pitch_um(display: Display) -> float | None:
    return None if display.layout is None else float(display.layout.period_um[0])
