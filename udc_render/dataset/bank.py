"""A kernel bank: the panels an online degradation draws from (restore.degrade), one folder on disk.

    DIR/bank.json            the bank's settings and one record per panel (the order is the panels' index)
    DIR/panel_<i>.npz        its arrays: kernels [3, S, S] (R, G, B at the sensor pitch, unit sum), and when
                             d > 0 the field: bases [3, r, S, S], coeffs [3, n, r], live [n, 2] (phase (j, i)),
                             shifts_x_um [Px], shifts_y_um [Py], field_power [3, Py, Px], series [3, 2a+1, b+1]
                             (complex; absent for an aperiodic display); with a far field far_kernels [3, Sf, Sf]

A panel is the per-channel form of the numpy synthesis (udc_render.pipeline, form 'per_channel'):

    DN = black + g · min(Poisson(γ_c / gain · FW · (x_c ⊗ k_c)) + read noise + FPN offsets, FW), defects

with the display's γ (T and gain per channel, optics.gamma), its sensor (gain, noise model, levels), the
sensor's defect pixels and fixed-pattern noise; where d > 0 the blur is the field blend of optics.field
(source blend, the exact power m(s(x)) of optics.field_power) of each channel's rank-r basis of phase
kernels: y_c = Σ_r B_cr ⊗ (W_cr · x_c), W_cr = Σ_q c_qr w_q(x) m_c(s(x)) (an exact blend is the rank of
all live phases with c = I). Where the synthesis it stands for (the physical profile's spectral form) has
them, a panel also carries the light past the kernel window (PanelFar: optics.far_field per channel) and its
display's haze (PanelHaze: optics.stray), applied by restore.degrade_wide; each record's "effects" lists what
the panel applies and what it does not, and why. Written by udc_render.dataset.bank_make; read here, without
torch.

Formats: 2 (today's), and 1, still read: a format-1 bank (made before panels carried the far field and the
haze) has neither, whatever its records say was drawn (FORMAT_1_EFFECTS); the shipped randomized models of
restore/trained were trained through such banks, their bank.json kept byte for byte (its sha256 is the
fingerprint their train.json names).
"""
from __future__ import annotations

import hashlib
import json
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

from udc_render.dataset.plan import DatasetError
from udc_render.io.files import save_json, save_npz
from udc_render.sensor import DefectConfig, FpnConfig, SensorConfig

__all__ = ["BANK_FILE", "BANK_FORMAT", "FORMAT_1", "FORMAT_1_EFFECTS", "Bank", "BankError", "Panel", "PanelFar",
           "PanelField", "PanelHaze", "bank_json_fingerprint", "file_sha256", "panel_effects", "read_bank",
           "read_panel", "save_panel", "write_bank_json"]

BANK_FORMAT = "udc-render kernel bank 2"
FORMAT_1 = "udc-render kernel bank 1"
BANK_FILE = "bank.json"
FIELD_ARRAYS = ("bases", "coeffs", "live", "shifts_x_um", "shifts_y_um", "field_power")
# what a format-1 panel does not apply (its records may name a drawn haze: it was recorded, never applied)
FORMAT_1_EFFECTS = {"far field": "not applied: a format-1 bank has none (the light past the kernel window is lost)",
                    "haze": "not applied: a format-1 bank has none (a drawn haze was recorded, not applied)"}


class BankError(DatasetError):
    """A bank folder or panel that cannot be used; one line."""


@dataclass(frozen=True, eq=False)
class PanelField:
    """The d > 0 field of one panel (module doc): per channel c, k_q ≈ Σ_r coeffs[c, q, r] bases[c, r] over the
    live phases (j, i); w_q the bilinear phase weights of optics.field.phase_weights over the shifts; the exact
    power series of optics.field_power (None: the phases' powers field_power, interpolated)."""
    bases: np.ndarray  # [3, r, S, S]
    coeffs: np.ndarray  # [3, n, r] float64
    live: tuple  # ((j, i), ...) n phases
    shifts_x_um: np.ndarray  # [Px]
    shifts_y_um: np.ndarray  # [Py]
    periodic: tuple[bool, bool]  # (y, x)
    period_um: tuple[float, float]  # (x, y)
    distance_mm: float
    image_distance_um: float
    field_power: np.ndarray  # [3, Py, Px]
    series: np.ndarray | None  # [3, 2a+1, b+1] complex128

    @property
    def rank(self) -> int:
        return int(self.bases.shape[1])


@dataclass(frozen=True, eq=False)
class PanelFar:
    """The light past the kernel window in the per-channel form: y_c += x̄_c ⊗ F_c, x̄ the coarse_px × coarse_px
    block means of the clean image (its frame with the kernel's margin, continued as its edge beyond: optics.
    far_field.far_light), F_c = Σ_k W_ck T_k τ_k f_k / Σ_k W_ck T_k τ_k (1 − o_k) [3, Sf, Sf] per coarse pixel: the
    band far fields f_k of the spectral synthesis weighted as γ weights the bands (W the camera's electrons of the
    monitor's white, T τ the display's transmission and its kernels' transmittance, o their energy outside the
    window), relative to the core's light (γ scales both)."""
    kernels: np.ndarray  # [3, Sf, Sf] float64
    coarse_px: int

    @property
    def share_rgb(self) -> list[float]:
        """The far field's light per channel, a share of the core's (what the window loses, within the lens's
        acceptance)."""
        return [float(v) for v in self.kernels.sum(axis=(-2, -1))]


@dataclass(frozen=True)
class PanelHaze:
    """The display stack's haze (optics.stray, effect d): e ← (1 − share) e + share (e ⊗ ρ_tail(θ ≥ inner_deg)) on
    the frame's electrons, after the blur and the far field."""
    share: float
    inner_deg: float


@dataclass(frozen=True, eq=False)
class Panel:
    """One panel of a bank: its name, per-channel kernels [3, S, S] at the sensor pitch pitch_um, γ (R, G, B)
    relative to glass at gain 1, the sensor behind it (gain = the display's, gamma_rggb = γ / gain, its noise
    model, exposure and levels), its defect pixels and fixed-pattern noise (None: none), the field (d > 0) and
    its record in bank.json (its "effects": what it applies; panel_effects), the far field and the haze (None:
    none). maps: 'frame', the defect and FPN maps of the whole frame drawn from their seeds (a
    crop takes its region, as the numpy synthesis's frame); 'crop', maps of a crop's own size from the seeds (a
    capture drawn per crop: restore.captures)."""
    name: str
    kernels: np.ndarray
    pitch_um: float
    gamma_rgb: tuple[float, float, float]
    sensor: SensorConfig
    defects: DefectConfig | None
    fpn: FpnConfig | None
    field: PanelField | None
    record: dict
    maps: str = "frame"
    far: PanelFar | None = None
    haze: PanelHaze | None = None

    @property
    def kernel_px(self) -> int:
        return int(self.kernels.shape[-1])

    @property
    def margin_px(self) -> int:
        """The margin a crop needs on every side: the kernel's half-width."""
        return self.kernel_px // 2


@dataclass(frozen=True)
class Bank:
    """A bank read from its folder: the settings of bank.json and the panels in their order."""
    folder: Path
    settings: dict
    panels: list[Panel]

    @property
    def fingerprint(self) -> str:
        """sha256 of bank.json (which names every panel file's sha256): what a training run records."""
        return bank_json_fingerprint(self.folder / BANK_FILE)

    @property
    def margin_px(self) -> int:
        return max(p.margin_px for p in self.panels)


def bank_json_fingerprint(path: Path) -> str:
    """The first 16 hex digits of a bank.json's sha256 (Bank.fingerprint; a carried copy's too)."""
    return hashlib.sha256(Path(path).read_bytes()).hexdigest()[:16]


def panel_file(index: int, name: str) -> str:
    return f"panel_{index:03d}_{name}.npz"


def file_sha256(path: Path) -> str:
    return hashlib.sha256(Path(path).read_bytes()).hexdigest()


def panel_record(panel: Panel, file: str, sha256: str, extra: dict) -> dict:
    """A panel's line of bank.json: every scalar that makes it (the arrays are in its file)."""
    f = panel.field
    field = None if f is None else {
        "rank": f.rank, "live_phases": len(f.live), "periodic": list(f.periodic), "period_um": list(f.period_um),
        "distance_mm": f.distance_mm, "image_distance_um": f.image_distance_um, "series": f.series is not None}
    far = None if panel.far is None else {"coarse_px": panel.far.coarse_px, "share_rgb": panel.far.share_rgb,
                                          "far_kernel_px": int(panel.far.kernels.shape[-1])}
    return {"name": panel.name, "file": file, "sha256": sha256, "pitch_um": panel.pitch_um,
            "kernel_px": panel.kernel_px, "gamma_rgb": list(panel.gamma_rgb), "sensor": asdict(panel.sensor),
            "defects": None if panel.defects is None else asdict(panel.defects),
            "fpn": None if panel.fpn is None else asdict(panel.fpn), "field": field, **extra, "far_field": far,
            "haze": None if panel.haze is None else asdict(panel.haze)}


def panel_effects(panel: Panel, not_applied: dict) -> dict:
    """What a panel applies to a clean crop, in order, and what it does not (not_applied: {effect: why}): the
    "effects" of its record."""
    s = panel.sensor
    applied = ["blur: the per-channel kernels (x ⊗ k)" + ("; d > 0: the field blend" if panel.field else "")]
    if panel.far is not None:
        applied.append(f"far field: {', '.join(f'{v:.4g}' for v in panel.far.share_rgb)} of the core's light (R, G, "
                       f"B), at {panel.far.coarse_px}-px coarse pixels")
    applied += ["γ (R, G, B) and the display's gain"] + ["cos⁴ fall-off"] * s.cos4_falloff
    if panel.haze is not None:
        applied.append(f"haze: {panel.haze.share:g} of the light into a θ⁻² veil from {panel.haze.inner_deg:g}°")
    applied += ["fixed-pattern noise"] * (panel.fpn is not None) + [f"noise: {s.noise}"]
    applied.append("full well, quantisation, black and white levels")
    applied += ["dead and hot pixels"] * (panel.defects is not None)
    return {"applied": applied, "not_applied": not_applied}


def panel_arrays(panel: Panel) -> dict:
    """The npz arrays of a panel (module doc)."""
    out = {"kernels": np.asarray(panel.kernels, np.float32)}
    if panel.far is not None:
        out["far_kernels"] = np.asarray(panel.far.kernels, np.float64)
    f = panel.field
    if f is not None:
        out.update(bases=np.asarray(f.bases, np.float32), coeffs=np.asarray(f.coeffs, np.float64),
                   live=np.asarray(f.live, np.int64).reshape(-1, 2), shifts_x_um=np.asarray(f.shifts_x_um, float),
                   shifts_y_um=np.asarray(f.shifts_y_um, float), field_power=np.asarray(f.field_power, float))
        if f.series is not None:
            out["series"] = np.asarray(f.series, np.complex128)
    return out


def _fail(folder: Path, what: str):
    raise BankError(f"--bank {folder}: {what}")


def read_panel(folder: Path, record: dict, fmt: str = BANK_FORMAT) -> Panel:
    """The panel of one bank.json record of format `fmt`, its file checked against the recorded sha256."""
    path = folder / record["file"]
    if not path.is_file():
        _fail(folder, f"{record['file']} is missing (re-run `udc-render bank` on this folder to finish it)")
    if file_sha256(path) != record["sha256"]:
        _fail(folder, f"{record['file']} differs from its sha256 in {BANK_FILE} (a damaged or replaced file: "
                      "delete it and re-run `udc-render bank`)")
    with np.load(path) as z:
        a = {k: z[k] for k in z.files}
    kernels = a["kernels"]
    if kernels.ndim != 3 or kernels.shape[0] != 3 or kernels.shape[1] != kernels.shape[2] or kernels.shape[1] % 2 == 0:
        _fail(folder, f"{record['file']}: kernels of shape {kernels.shape}: expected [3, S, S] with S odd")
    field = None
    if record["field"] is not None:
        missing = [k for k in FIELD_ARRAYS if k not in a]
        if missing:
            _fail(folder, f"{record['file']}: no {missing[0]} array for its d > 0 field")
        f = record["field"]
        field = PanelField(a["bases"], a["coeffs"], tuple(map(tuple, a["live"].tolist())), a["shifts_x_um"],
                           a["shifts_y_um"], tuple(f["periodic"]), tuple(f["period_um"]), float(f["distance_mm"]),
                           float(f["image_distance_um"]), a["field_power"], a.get("series"))
    sensor = SensorConfig(**{k: tuple(v) if isinstance(v, list) else v for k, v in record["sensor"].items()})
    defects = None if record["defects"] is None else DefectConfig(**record["defects"])
    fpn = None if record["fpn"] is None else FpnConfig(**record["fpn"])
    if fmt == FORMAT_1:
        return Panel(record["name"], kernels, float(record["pitch_um"]), tuple(record["gamma_rgb"]), sensor, defects,
                     fpn, field, {**record, "effects": {"format": FORMAT_1, "not_applied": FORMAT_1_EFFECTS}})
    far = None
    if record["far_field"] is not None:
        if "far_kernels" not in a:
            _fail(folder, f"{record['file']}: no far_kernels array for its far field")
        far = PanelFar(a["far_kernels"], int(record["far_field"]["coarse_px"]))
    haze = None if record["haze"] is None else PanelHaze(float(record["haze"]["share"]),
                                                         float(record["haze"]["inner_deg"]))
    return Panel(record["name"], kernels, float(record["pitch_um"]), tuple(record["gamma_rgb"]), sensor, defects, fpn,
                 field, record, far=far, haze=haze)


def read_bank(folder: Path, names: list[str] | None = None) -> Bank:
    """The bank in `folder` (every panel, or those named), each file checked; one-line BankError otherwise."""
    folder = Path(folder)
    path = folder / BANK_FILE
    if not path.is_file():
        _fail(folder, f"no {BANK_FILE}: expected a folder written by `udc-render bank`")
    try:
        doc = json.loads(path.read_text())
    except (OSError, ValueError) as e:
        _fail(folder, f"{BANK_FILE} is not readable JSON ({e})")
    if not isinstance(doc, dict) or doc.get("format") not in (BANK_FORMAT, FORMAT_1):
        _fail(folder, f"{BANK_FILE}: format {doc.get('format') if isinstance(doc, dict) else None!r}: expected "
                      f"{BANK_FORMAT!r} (or {FORMAT_1!r})")
    records = doc.get("panels", [])
    if doc.get("complete") is not True or not records:
        _fail(folder, f"the bank is not complete ({len(records)} of {doc.get('count')} panels): re-run "
                      "`udc-render bank` on this folder to finish it")
    if names:
        known = [r["name"] for r in records]
        unknown = [n for n in names if n not in known]
        if unknown:
            _fail(folder, f"--display {unknown[0]!r} is not a panel of this bank (it has {', '.join(known)})")
        records = [r for r in records if r["name"] in names]
    settings = {k: v for k, v in doc.items() if k != "panels"}
    return Bank(folder, settings, [read_panel(folder, r, doc["format"]) for r in records])


def save_panel(folder: Path, index: int, panel: Panel) -> dict:
    """Write panel `index`'s file (atomic) and return its bank.json record."""
    file = panel_file(index, panel.name)
    save_npz(Path(folder) / file, **panel_arrays(panel))
    return panel_record(panel, file, file_sha256(Path(folder) / file), panel.record)


def write_bank_json(folder: Path, settings: dict, records: list[dict], count: int) -> None:
    """bank.json (atomic), complete when every one of `count` panels is recorded."""
    save_json(Path(folder) / BANK_FILE, {**settings, "format": BANK_FORMAT, "count": count,
                                         "complete": len(records) == count, "panels": records})
