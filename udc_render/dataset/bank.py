"""A kernel bank: the panels an online degradation draws from (restore.degrade), one folder on disk.

    DIR/bank.json            the bank's settings and one record per panel (the order is the panels' index)
    DIR/panel_<i>.npz        its arrays: kernels [3, S, S] (R, G, B at the sensor pitch, unit sum), and when
                             d > 0 the field: bases [3, r, S, S], coeffs [3, n, r], live [n, 2] (phase (j, i)),
                             shifts_x_um [Px], shifts_y_um [Py], field_power [3, Py, Px], series [3, 2a+1, b+1]
                             (complex; absent for an aperiodic display)

A panel is the per-channel form of the numpy synthesis (udc_render.pipeline, form 'per_channel'):

    DN = black + g · min(Poisson(γ_c / gain · FW · (x_c ⊗ k_c)) + read noise + FPN offsets, FW), defects

with the display's γ (T and gain per channel, optics.gamma), its sensor (gain, noise model, levels), the
sensor's defect pixels and fixed-pattern noise; where d > 0 the blur is the field blend of optics.field
(source blend, the exact power m(s(x)) of optics.field_power) of each channel's rank-r basis of phase
kernels: y_c = Σ_r B_cr ⊗ (W_cr · x_c), W_cr = Σ_q c_qr w_q(x) m_c(s(x)) (an exact blend is the rank of
all live phases with c = I). Written by udc_render.dataset.bank_make; read here, without torch.
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

BANK_FORMAT = "udc-render kernel bank 1"
BANK_FILE = "bank.json"
FIELD_ARRAYS = ("bases", "coeffs", "live", "shifts_x_um", "shifts_y_um", "field_power")


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
class Panel:
    """One panel of a bank: its name, per-channel kernels [3, S, S] at the sensor pitch pitch_um, γ (R, G, B)
    relative to glass at gain 1, the sensor behind it (gain = the display's, gamma_rggb = γ / gain, its noise
    model, exposure and levels), its defect pixels and fixed-pattern noise (None: none), the field (d > 0) and
    its record in bank.json. maps: 'frame', the defect and FPN maps of the whole frame drawn from their seeds (a
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
    return {"name": panel.name, "file": file, "sha256": sha256, "pitch_um": panel.pitch_um,
            "kernel_px": panel.kernel_px, "gamma_rgb": list(panel.gamma_rgb), "sensor": asdict(panel.sensor),
            "defects": None if panel.defects is None else asdict(panel.defects),
            "fpn": None if panel.fpn is None else asdict(panel.fpn), "field": field, **extra}


def panel_arrays(panel: Panel) -> dict:
    """The npz arrays of a panel (module doc)."""
    out = {"kernels": np.asarray(panel.kernels, np.float32)}
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


def read_panel(folder: Path, record: dict) -> Panel:
    """The panel of one bank.json record, its file checked against the recorded sha256."""
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
    return Panel(record["name"], kernels, float(record["pitch_um"]), tuple(record["gamma_rgb"]), sensor, defects, fpn,
                 field, record)


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
    if not isinstance(doc, dict) or doc.get("format") != BANK_FORMAT:
        _fail(folder, f"{BANK_FILE}: format {doc.get('format') if isinstance(doc, dict) else None!r}: expected "
                      f"{BANK_FORMAT!r}")
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
    return Bank(folder, settings, [read_panel(folder, r) for r in records])


def save_panel(folder: Path, index: int, panel: Panel) -> dict:
    """Write panel `index`'s file (atomic) and return its bank.json record."""
    file = panel_file(index, panel.name)
    save_npz(Path(folder) / file, **panel_arrays(panel))
    return panel_record(panel, file, file_sha256(Path(folder) / file), panel.record)


def write_bank_json(folder: Path, settings: dict, records: list[dict], count: int) -> None:
    """bank.json (atomic), complete when every one of `count` panels is recorded."""
    save_json(Path(folder) / BANK_FILE, {**settings, "format": BANK_FORMAT, "count": count,
                                         "complete": len(records) == count, "panels": records})
