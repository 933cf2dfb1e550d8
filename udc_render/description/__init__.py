"""The panel's description: what a restorer may know about the panel in front of its sensor, in one typed form
that every producer writes (a bank's panel, a preset or display file, `udc-render fit`'s folder:
udc_render.description.make) and every consumer reads (a restorer conditioned on the panel, `evaluate
--display FILE`, the training API restore.api). numpy only (no torch): restore turns it into tensors.

Conventions (PanelDescription's fields):
    kernels      [3, K, K] float32: R, G, B at the packed planes' pitch (2 × the sensor pitch: one packed pixel is one
                 RGGB cell, what a restorer's [4, H/2, W/2] input sees), centred at K // 2, unit sum over the window.
                 K = DESCRIPTION_KERNEL_PX (129 packed px, ±128 sensor px) whatever the crop or the bank's kernel
                 size: a bank's larger kernel is cut to the window, a smaller one padded with zeros. Both Gr and
                 Gb see G. d > 0: the power-weighted mean over the field phases (psf.KernelSet.kernels: the frame's
                 mean blur), the phases themselves in `field`.
    outside_rgb  [3] the share of the channel's light outside the K × K window: of all the light the kernel
                 computation sees (the engine's energy_outside, within the lens's acceptance) for a display; of the
                 bank's window and its far field for a bank's panel (udc_render.description.make).
    field        d > 0 only (None at d = 0): FieldDescription, the rank-r basis of the phase kernels at the packed
                 pitch in the same window (udc_render.dataset.bank.PanelField's, its bases packed like `kernels`).
    gamma_rggb   [4] γ per packed channel R, Gr, Gb, B (optics.gamma: the level of a white through the panel at its
                 gain, relative to glass at gain 1): the normalised input w ≈ γ · (clean ⊗ k) per channel, the clean
                 image in units of the white level at gain 1 (gt.exr's).
    gain         the sensor's analogue gain behind this panel (the display's).
    noise        the sensor's noise model ('poisson', 'gaussian', 'none'); lambda_read, lambda_shot [4] (R, Gr, Gb,
                 B): var(w) = λ_read + λ_shot · w of the normalised input w = (DN − black) / (white − black):
                 the photon model's equivalent (sensor.noise.sensor_lambdas: λ_shot = g / R, λ_read = (g σ_read /
                 R)², quantisation and fixed-pattern noise excluded), the Gaussian model's own, 0 for 'none'.
    saturation   w at which the full well clips: g · FW / R (≥ 1: the white level clips first).
    black_level_dn, white_level_dn, bit_depth   the packed input's levels.
    camera, sensor_pitch_um, frame_px (width, height)   the sensor and frame the description was made for.
    name, source where it came from ('bank panel …', 'preset …', 'display file …', 'fit …').

The identity of a description (DescriptionSpec: camera, sensor pitch, frame, bits and levels, kernel window) is
what a model trained on descriptions must be given again: check_spec names the first key that differs.
Records: to_record() → (JSON-able dict, {name: array}); from_record reads them back; save / load write
<path>.json and <path>.npz (atomic).
"""
from __future__ import annotations

import json
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

from udc_render.errors import UdcError
from udc_render.io.files import save_json, save_npz

__all__ = ["DESCRIPTION_KERNEL_PX", "DescriptionError", "DescriptionSpec", "FieldDescription", "PanelDescription",
           "check_spec", "load", "packed_window", "save", "symmetric_modes"]

DESCRIPTION_KERNEL_PX = 129
RECORD_FORMAT = "udc-render panel description 1"
FIELD_ARRAYS = ("bases", "coeffs", "live", "shifts_x_um", "shifts_y_um")


class DescriptionError(UdcError):
    """A description that cannot be made, read or used; one line naming what is missing or differs."""


@dataclass(frozen=True, eq=False)
class FieldDescription:
    """The d > 0 field at the packed pitch: per channel c, the phase kernel of live phase q (j, i) is
    ≈ Σ_r coeffs[c, q, r] bases[c, r]; the phases sit at shifts_x_um[i], shifts_y_um[j] of the display (image
    position = shift · image_distance_um / d) over period_um (x, y)."""
    bases: np.ndarray  # [3, r, K, K] float32
    coeffs: np.ndarray  # [3, n, r] float64
    live: tuple  # ((j, i), ...) n phases
    shifts_x_um: np.ndarray
    shifts_y_um: np.ndarray
    period_um: tuple[float, float]
    distance_mm: float
    image_distance_um: float

    @property
    def rank(self) -> int:
        return int(self.bases.shape[1])


@dataclass(frozen=True)
class DescriptionSpec:
    """What a description was made for, beyond the panel: a conditioned model's inputs must share it."""
    camera: str
    sensor_pitch_um: float
    frame_px: tuple[int, int]
    bit_depth: int
    black_level_dn: int
    white_level_dn: int
    kernel_px: int


@dataclass(frozen=True, eq=False)
class PanelDescription:
    """A panel's description (module doc: fields and conventions)."""
    name: str
    source: str
    kernels: np.ndarray  # [3, K, K] float32
    outside_rgb: tuple[float, float, float]
    gamma_rggb: tuple[float, float, float, float]
    gain: float
    noise: str
    lambda_read: tuple[float, float, float, float]
    lambda_shot: tuple[float, float, float, float]
    saturation: float
    black_level_dn: int
    white_level_dn: int
    bit_depth: int
    camera: str
    sensor_pitch_um: float
    frame_px: tuple[int, int]
    field: FieldDescription | None = None

    def __post_init__(self):
        k = np.asarray(self.kernels)
        if k.ndim != 3 or k.shape[0] != 3 or k.shape[1] != k.shape[2] or k.shape[1] % 2 == 0:
            raise DescriptionError(f"description {self.name}: kernels of shape {k.shape}: expected [3, K, K], K odd")
        if len(self.gamma_rggb) != 4 or len(self.lambda_read) != 4 or len(self.lambda_shot) != 4:
            raise DescriptionError(f"description {self.name}: γ and λ need 4 values (R, Gr, Gb, B)")

    @property
    def kernel_px(self) -> int:
        return int(self.kernels.shape[-1])

    @property
    def pitch_um(self) -> float:
        """The kernels' pitch: the packed planes', 2 × the sensor pitch."""
        return 2.0 * self.sensor_pitch_um

    @property
    def kernels_rggb(self) -> np.ndarray:
        """[4, K, K] float32: R, Gr, Gb, B (both greens G), the packed input's channel order."""
        return np.ascontiguousarray(self.kernels[[0, 1, 1, 2]])

    def spec(self) -> DescriptionSpec:
        return DescriptionSpec(self.camera, float(self.sensor_pitch_um), tuple(int(v) for v in self.frame_px),
                               int(self.bit_depth), int(self.black_level_dn), int(self.white_level_dn),
                               self.kernel_px)

    def to_record(self) -> tuple[dict, dict[str, np.ndarray]]:
        """(the JSON-able scalars, the arrays): what travels with a checkpoint or a batch (from_record)."""
        meta = {k: v for k, v in asdict(self).items() if k not in ("kernels", "field")}
        meta = json.loads(json.dumps(meta))
        arrays = {"kernels": np.asarray(self.kernels, np.float32)}
        f = self.field
        if f is not None:
            meta["field"] = {"period_um": list(f.period_um), "distance_mm": f.distance_mm,
                             "image_distance_um": f.image_distance_um}
            arrays.update({"field_" + k: np.asarray(getattr(f, k)) for k in FIELD_ARRAYS})
        return {"format": RECORD_FORMAT, **meta}, arrays

    @classmethod
    def from_record(cls, meta: dict, arrays: dict) -> PanelDescription:
        if meta.get("format") != RECORD_FORMAT:
            raise DescriptionError(f"description record: format {meta.get('format')!r}: expected {RECORD_FORMAT!r}")
        field = None
        if meta.get("field") is not None:
            f = meta["field"]
            field = FieldDescription(*(np.asarray(arrays["field_" + k]) for k in FIELD_ARRAYS[:2]),
                                     tuple(map(tuple, np.asarray(arrays["field_live"]).tolist())),
                                     np.asarray(arrays["field_shifts_x_um"]), np.asarray(arrays["field_shifts_y_um"]),
                                     tuple(f["period_um"]), float(f["distance_mm"]), float(f["image_distance_um"]))
        scalars = {k: tuple(v) if isinstance(v, list) else v for k, v in meta.items() if k not in ("format", "field")}
        return cls(kernels=np.asarray(arrays["kernels"], np.float32), field=field, **scalars)


def save(path: Path, description: PanelDescription) -> None:
    """<path>.json and <path>.npz (each atomic)."""
    meta, arrays = description.to_record()
    path = Path(path)
    save_npz(path.with_suffix(".npz"), **arrays)
    save_json(path.with_suffix(".json"), meta)


def load(path: Path) -> PanelDescription:
    """The description saved at <path>.json / <path>.npz."""
    path = Path(path)
    files = [path.with_suffix(s) for s in (".json", ".npz")]
    if not all(p.is_file() for p in files):
        raise DescriptionError(f"{path}: expected {files[0].name} and {files[1].name} (udc_render.description.save)")
    with np.load(files[1]) as z:
        arrays = {k: z[k] for k in z.files}
    return PanelDescription.from_record(json.loads(files[0].read_text()), arrays)


def check_spec(expected: DescriptionSpec | dict, description: PanelDescription, who: str = "the model") -> None:
    """Refuse a description made for another sensor or frame than `expected` (a model's): one line naming the
    first key that differs, both values."""
    want = asdict(expected) if isinstance(expected, DescriptionSpec) else dict(expected)
    have = asdict(description.spec())
    for key, value in want.items():
        got = have.get(key)
        same = np.allclose(got, value, rtol=1e-9) if key == "sensor_pitch_um" else list(np.atleast_1d(got)) == \
            list(np.atleast_1d(value))
        if not same:
            raise DescriptionError(f"panel description {description.name!r} ({description.source}): {key} = {got!r}, "
                                   f"but {who} was made for {key} = {value!r}")


def packed_window(kernels_sensor: np.ndarray, kernel_px: int = DESCRIPTION_KERNEL_PX, normalise: bool = True
                  ) -> tuple[np.ndarray, np.ndarray]:
    """(kernels [..., K, K] at the packed pitch, unit sum; the share outside the window [...]) of kernels
    [..., S, S] at the sensor pitch (S odd, centre c = S // 2, unit sum or not): each integrated over a packed
    pixel (2 × 2 sensor pixels) centred on the kernel's centre and sampled every 2 pixels,
        k[i, j] = Σ_{a, b ∈ {−1, 0, 1}} h(a) h(b) K[c + 2i + a, c + 2j + b],  h = (½, 1, ½),  |i|, |j| ≤ c // 2,
    (a sensor-pitch delta becomes a packed delta, a shift of 2 px one of 1 px), then cut (or zero-padded) to
    K × K about the centre and normalised (window; normalise False: a field's bases, which are not kernels)."""
    k = np.asarray(kernels_sensor, np.float64)
    if k.ndim < 2 or k.shape[-1] != k.shape[-2] or k.shape[-1] % 2 == 0:
        raise DescriptionError(f"kernels: shape {k.shape}: expected [..., S, S] with S odd")
    pad = [(0, 0)] * (k.ndim - 2) + [(1, 1), (1, 1)]
    p = np.pad(k, pad)
    box = 0.5 * p[..., :-2, :] + p[..., 1:-1, :] + 0.5 * p[..., 2:, :]
    box = 0.5 * box[..., :-2] + box[..., 1:-1] + 0.5 * box[..., 2:]
    c = k.shape[-1] // 2
    return window(box[..., c % 2::2, c % 2::2], kernel_px, normalise)


def window(kernels: np.ndarray, kernel_px: int = DESCRIPTION_KERNEL_PX, normalise: bool = True
           ) -> tuple[np.ndarray, np.ndarray]:
    """(kernels [..., K, K] cut or zero-padded about the centre of [..., S, S] (S, K odd), unit sum (normalise); the
    share of each kernel's sum outside the window)."""
    if kernel_px < 1 or kernel_px % 2 == 0:
        raise DescriptionError(f"kernel_px = {kernel_px}: expected an odd number of pixels (a centred kernel)")
    k = np.asarray(kernels, np.float64)
    s, h = k.shape[-1], kernel_px // 2
    total = k.sum(axis=(-2, -1))
    if s < kernel_px:
        d = (kernel_px - s) // 2
        k = np.pad(k, [(0, 0)] * (k.ndim - 2) + [(d, d), (d, d)])
    else:
        k = k[..., s // 2 - h:s // 2 + h + 1, s // 2 - h:s // 2 + h + 1]
    inside = k.sum(axis=(-2, -1))
    with np.errstate(divide="ignore", invalid="ignore"):
        outside = np.where(total != 0, 1.0 - inside / total, 0.0)
    return (k / inside[..., None, None] if normalise else k).astype(np.float32), outside


# restore.data.dihedral's modes: bit 0 transpose, bit 1 flip rows, bit 2 flip columns
def _dihedral(k: np.ndarray, mode: int) -> np.ndarray:
    if mode & 1:
        k = np.swapaxes(k, -1, -2)
    if mode & 2:
        k = np.flip(k, -2)
    if mode & 4:
        k = np.flip(k, -1)
    return k


def symmetric_modes(kernels: np.ndarray, tolerance: float) -> tuple[tuple[int, ...], list[float]]:
    """(the modes 0–7 of restore.data.dihedral under which every channel's kernel [C, K, K] is unchanged:
    max |k − T(k)| / max k < tolerance per channel; the worst channel's value per mode). Mode 0 always."""
    k = np.asarray(kernels, np.float64)
    worst = [float(np.max(np.abs(k - _dihedral(k, m)).max(axis=(-2, -1)) / k.max(axis=(-2, -1)))) for m in range(8)]
    return tuple(m for m in range(8) if worst[m] < tolerance or m == 0), worst
