"""How a restorer conditioned on the panel gets the panel's description (udc_render.description), in training and
in evaluation.

A model that needs one says so: its class has NEEDS_DESCRIPTION = True, its forward is model(x, description) with
`description` the tensors of description_tensors, and its `description_spec` (a dict of udc_render.description.
DescriptionSpec: camera, sensor pitch, frame, bits and levels, kernel window) names what its descriptions were
made for. Tensors of a batch of B descriptions (description_tensors; float32 unless stated):

    kernels       [B, 3, K, K]   R, G, B at the packed pitch, unit sum (d > 0: the phases' power-weighted mean)
    outside       [B, 3]         the share of each kernel outside the window
    gamma         [B, 4]         γ per packed channel R, Gr, Gb, B
    gain          [B]            the sensor's analogue gain
    lambda_read   [B, 4]         var(w) = λ_read + λ_shot · w of the normalised input, per packed channel
    lambda_shot   [B, 4]
    saturation    [B]            w at which the full well clips
    black_level_dn, white_level_dn, bit_depth   [B] (float32)
    distance_mm   [B]            the display-to-lens gap (0: no field)

A d > 0 panel's field (its phase basis) stays in the PanelDescription records; the tensors carry its mean kernel.

In evaluation (`udc-render evaluate --model CHECKPOINT --display FILE`), each display's description is computed
by describe_display from the --display item (a preset, a display file, or `udc-render fit`'s folder or its
display.toml: describe_fit) for the dataset's sensor (capture.json) and frame, with the rig the dataset's
synth.json records (udc_render.description.make.dataset_rig): evaluation_descriptions. A model asked to restore
without a description it needs, or with one made for another sensor or frame, is refused in one line.
"""
from __future__ import annotations

import json
from dataclasses import asdict
from pathlib import Path

import numpy as np
import torch

from restore.data import DataError
from udc_render.description import DESCRIPTION_KERNEL_PX, DescriptionError, PanelDescription, check_spec

TENSOR_KEYS = ("kernels", "outside", "gamma", "gain", "lambda_read", "lambda_shot", "saturation", "black_level_dn",
               "white_level_dn", "bit_depth", "distance_mm")


def needs_description(model) -> bool:
    """Whether a model restores only with a panel description (module doc)."""
    return bool(getattr(model, "NEEDS_DESCRIPTION", False))


def description_tensors(descriptions: list[PanelDescription], device=None) -> dict[str, torch.Tensor]:
    """The tensors of a batch of descriptions (module doc), stacked in their order, on `device`."""
    if len({d.kernel_px for d in descriptions}) > 1:
        raise DescriptionError(f"descriptions of {sorted({d.kernel_px for d in descriptions})} px kernels: a batch "
                               "needs one kernel window")
    rows = {"kernels": [d.kernels for d in descriptions], "outside": [d.outside_rgb for d in descriptions],
            "gamma": [d.gamma_rggb for d in descriptions], "gain": [d.gain for d in descriptions],
            "lambda_read": [d.lambda_read for d in descriptions], "lambda_shot": [d.lambda_shot for d in descriptions],
            "saturation": [d.saturation for d in descriptions],
            "black_level_dn": [d.black_level_dn for d in descriptions],
            "white_level_dn": [d.white_level_dn for d in descriptions],
            "bit_depth": [d.bit_depth for d in descriptions],
            "distance_mm": [0.0 if d.field is None else d.field.distance_mm for d in descriptions]}
    return {k: torch.as_tensor(np.asarray(rows[k], np.float32), device=device) for k in TENSOR_KEYS}


def check_model_description(model, description: PanelDescription | None, name: str) -> None:
    """Refuse a model that needs a description without one, or with one made for another sensor or frame."""
    if description is None:
        raise DescriptionError(f"{name} restores only with the panel's description: give --display as a preset, a "
                               "display file or `udc-render fit`'s folder (its display.toml and sensor.toml)")
    spec = getattr(model, "description_spec", None)
    if spec is not None:
        check_spec(spec, description, who=name)


def empty_description_tensors(batch: int, kernel_px: int, device=None) -> dict[str, torch.Tensor]:
    """Zero tensors of description_tensors' shapes (a model's MACs counted on the meta device: restore.counting)."""
    shapes = {"kernels": (3, kernel_px, kernel_px), "outside": (3,), "gamma": (4,), "lambda_read": (4,),
              "lambda_shot": (4,)}
    return {k: torch.zeros((batch,) + shapes.get(k, ()), device=device) for k in TENSOR_KEYS}


def spec_kernel_px(model) -> int:
    """The kernel window of the descriptions a model was made for (its description_spec; else its kernel_px, else the
    default)."""
    own = getattr(model, "kernel_px", DESCRIPTION_KERNEL_PX)
    return int((getattr(model, "description_spec", None) or {}).get("kernel_px", own))


def evaluation_description(spec: str, pair, kernel_px: int | None = None) -> PanelDescription:
    """The description of --display item `spec` for a dataset pair's sensor, frame and rig, in a kernel_px window
    (None: the default) (module doc)."""
    from restore.data import load_gt
    from udc_render.description.make import dataset_rig, describe_display, describe_fit
    path = Path(spec)
    capture = json.loads((pair.folder / pair.display / "capture.json").read_text())
    h, w = load_gt(pair.folder).shape[1:]
    rig, k = dataset_rig(pair.folder), {} if kernel_px is None else {"kernel_px": kernel_px}
    if path.is_dir():
        return describe_fit(path, capture["sensor"], (w, h), rig, **k)
    if path.name == "display.toml" and (path.parent / "sensor.toml").is_file():
        return describe_fit(path.parent, capture["sensor"], (w, h), rig, **k)
    return describe_display(spec, capture["sensor"], (w, h), rig, **k)


def evaluation_descriptions(model, name: str, pairs_by_display: dict, specs: tuple | None) -> dict:
    """{display: its description} for a model that needs one (module doc), else {}: the --display items
    `specs` in the order of pairs_by_display's displays; each checked against the model (check_model_description)."""
    if not needs_description(model):
        return {}
    from udc_render.optics.displays import PRESETS, display_name
    known = {}
    for s in specs or ():
        if Path(s).is_dir() or Path(s).suffix or s in PRESETS:
            known[display_name(str(Path(s) / "display.toml") if Path(s).is_dir() else s)] = s
    out = {}
    for display, pairs in pairs_by_display.items():
        if display not in known:
            raise DataError(f"{name} restores only with the panel's description, and display {display!r} is none of "
                            "a preset, a display file or `udc-render fit`'s folder: give --display as one of those")
        out[display] = evaluation_description(known[display], pairs[0], spec_kernel_px(model))
        check_model_description(model, out[display], name)
    return out


def predict_described(model, packed: np.ndarray, description: PanelDescription, device: torch.device) -> np.ndarray:
    """[3, H, W] float32 restored image of one packed RAW [4, H/2, W/2] by a model that needs its description."""
    with torch.inference_mode():
        x = torch.from_numpy(np.ascontiguousarray(packed, np.float32))[None].to(device)
        return model(x.to(memory_format=torch.channels_last), description_tensors([description], device))[0] \
            .float().cpu().numpy()


def bank_descriptions(bank, kernel_px: int = DESCRIPTION_KERNEL_PX) -> list[PanelDescription]:
    """Each panel's description of a bank (describe_panel) on the frame its bank.json names (frame_px), in a
    kernel_px window."""
    from udc_render.description.make import describe_panel
    frame = bank.settings.get("frame_px")
    if frame is None:
        raise DataError(f"--bank {bank.folder}: its bank.json names no frame_px: a model that needs the panel's "
                        "description needs the sensor frame its panels were made for")
    return [describe_panel(p, (int(frame[0]), int(frame[1])), kernel_px) for p in bank.panels]


def crop_description(descriptions: list[PanelDescription], bank, draw: dict) -> PanelDescription:
    """The description of an online crop's draw (restore.online): its panel's, with the crop's own drawn sensor
    under capture draws (restore.captures)."""
    from restore.captures import captured_panel
    from udc_render.description.make import with_sensor
    base = descriptions[draw["panel"]]
    if "capture" not in draw:
        return base
    return with_sensor(base, captured_panel(bank.panels[draw["panel"]], draw["capture"]).sensor)


def described_spec(descriptions: list[PanelDescription]) -> dict:
    """The DescriptionSpec the descriptions share, as a JSON dict (a model's description_spec); refused in one line
    when two differ (check_spec)."""
    for d in descriptions[1:]:
        check_spec(descriptions[0].spec(), d, who=f"panel {descriptions[0].name!r} of the same bank")
    return json.loads(json.dumps(asdict(descriptions[0].spec())))


def check_description_source(model_config: dict, degrade: dict | None) -> None:
    """Refuse, in one line, training a model that needs the panel's description on a dataset's captures: only the
    online degradation's crops carry one (their bank panel's)."""
    from restore.models import MODELS
    if degrade is None and needs_description(MODELS.get(model_config.get("type"))):
        raise DescriptionError(f"--model {model_config['type']}: it restores with the panel's description, which "
                               "training gives only with the online degradation: use --degrade online --bank DIR")


class DescribedBatches:
    """Online training batches (restore.online.OnlineBatches) with each crop's description: epoch(e) gives (draws,
    batches of (x, y, description_tensors of the crops' crop_description)), on the batches' device."""

    def __init__(self, batches, descriptions: list[PanelDescription]):
        self.batches, self.descriptions = batches, descriptions
        self.images, self.count, self.record = batches.images, batches.count, batches.record

    def epoch(self, epoch: int):
        draws = self.batches.epoch_draws(epoch)
        return draws, self._described(draws)

    def _described(self, draws: list[dict]):
        b, dev, bank = self.batches.batch, self.batches.degrader.device, self.batches.bank
        for i, (x, y) in enumerate(self.batches.batches_of(draws)):
            chunk = draws[i * b:(i + 1) * b]
            yield x, y, description_tensors([crop_description(self.descriptions, bank, d) for d in chunk], dev)


def described_training(model, data, val_count: int) -> tuple[object, list | None]:
    """(the training batches, the validation images' descriptions or None): for a model that needs the panel's
    description, its online batches as DescribedBatches, validation image j's description that of panel j mod N
    (restore.online.validation_pairs degrades it so), in the model's kernel window (spec_kernel_px), and its
    description_spec set to the bank's; else as given."""
    if not needs_description(model):
        return data, None
    descriptions = bank_descriptions(data.bank, spec_kernel_px(model))
    model.set_description_spec(described_spec(descriptions))
    return DescribedBatches(data, descriptions), [descriptions[j % len(descriptions)] for j in range(val_count)]
