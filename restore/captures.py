"""A capture of its own for every crop of the online degradation (`udc-render train --degrade online
--capture-draws bank|default|FILE.toml`, restore.online): the crop's sensor and exposure drawn from the
distributions' sensor.* and exposure.* (udc_render.dataset.randomize.draw_capture, the draws a randomized
dataset's item makes), through the kernels of its panel. `bank` takes the distributions a randomized bank was
drawn from (its bank.json's "randomize"). Without it a crop takes its panel's capture, so N panels
give N sensors and N brightness levels.

A crop's capture replaces on its panel (captured_panel):
- the gain: the panel's family gain (its gain ÷ its own gain_scale) × the crop's gain_scale;
- the exposure: the panel's exposure rule (its exposure ÷ its own exposure.scale) × the crop's exposure.scale;
- the read noise and the fixed-pattern noise (PRNU, DSNU, row and column offsets, dark current, and the maps'
  seed);
- the defect pixels (dead and hot fractions, the hot pixels' dark current, and the map's seed);
- the brightness of the clean scene (exposure.brightness).
Its defect map and FPN maps are its own: maps of the crop's size drawn from its seeds (Panel.maps 'crop':
sensor.defects.defect_map and sensor.fpn.fpn_normals of a crop-sized sensor, restore.degrade_sensor.FrameMaps),
a crop's own pixels' draws, where the frame's would cost a frame's for each crop. A panel without defects or FPN
keeps none. The crop's drawn values (CROP_KEYS, then the two maps' seeds) go into online.jsonl. Validation keeps
each panel's own capture: a fixed set, comparable between epochs and runs.

Streams: crop k of epoch e draws with draw_capture(…, seed = stream_seed(seed, 'online capture', e), item = k)
(restore.tensors.stream_seed: the named stream of udc_render.streams): a crop's capture depends on (seed, epoch, k)
alone, as its image and panel do.
"""
from __future__ import annotations

import hashlib
import json
from dataclasses import dataclass, replace

from restore.tensors import stream_seed
from udc_render.dataset.bank import Bank, Panel
from udc_render.dataset.randomize import (
    CaptureDraw,
    Distributions,
    RandomizeError,
    draw_capture,
    load_distributions,
    parse,
)

BANK = "bank"  # --capture-draws bank: the bank's own distributions

CROP_KEYS = ("sensor.gain_scale", "sensor.read_noise_e", "sensor.prnu", "sensor.dsnu_e", "sensor.row_offset_e",
             "sensor.column_offset_e", "sensor.dark_current_e_per_s", "sensor.dead_fraction", "sensor.hot_fraction",
             "sensor.hot_dark_e_per_s", "exposure.scale", "exposure.brightness")


@dataclass(frozen=True)
class CaptureDraws:
    """The distributions that every crop's capture is drawn from, and the --capture-draws they came from."""
    spec: str
    dists: Distributions

    def describe(self) -> dict:
        """What a training run records (train.json) and a resumed one must match: the spec and the sha256 of the
        distributions (not of where they came from)."""
        parameters = self.dists.describe()["parameters"]
        return {"spec": self.spec, "sha256": hashlib.sha256(json.dumps(parameters, sort_keys=True).encode())
                .hexdigest()[:16]}


def load_capture_draws(spec: str, bank: Bank | None = None) -> CaptureDraws:
    """'default' (the documented ranges), a TOML file of distributions (udc_render.dataset.randomize), or 'bank':
    those `bank` was drawn from (`udc-render bank --randomize`)."""
    if str(spec) != BANK:
        return CaptureDraws(str(spec), load_distributions(spec))
    if bank is None:
        raise RandomizeError(f"--capture-draws {BANK}: needs the bank (--bank DIR) whose distributions to draw from")
    drawn = (bank.settings.get("randomize") or {}).get("parameters")
    if not drawn:
        raise RandomizeError(f"--capture-draws {BANK}: the bank {bank.folder} was not drawn (`udc-render bank "
                             "--randomize`): expected default or a .toml file of distributions")
    return CaptureDraws(BANK, parse(drawn, f"{bank.folder}/bank.json: randomize"))


def crop_capture(draws: CaptureDraws, seed: int, epoch: int, k: int) -> CaptureDraw:
    """Crop k of epoch `epoch`'s capture (module doc: its streams)."""
    return draw_capture(draws.dists, 1, stream_seed(seed, "online capture", int(epoch)), int(k))


def captured_panel(panel: Panel, cap: CaptureDraw) -> Panel:
    """The panel as capture `cap` sees it (module doc): its kernels, far field and haze; the capture's gain,
    exposure, read noise, FPN and defect pixels, their maps drawn per crop (a panel without FPN or defects keeps
    none)."""
    own = panel.record.get("capture_draw", {})
    sensor = replace(panel.sensor, gain=panel.sensor.gain / own.get("gain_scale", 1.0) * cap.gain_scale,
                     exposure_s=panel.sensor.exposure_s / own.get("exposure_scale", 1.0) * cap.exposure_scale,
                     read_noise_e=float(cap.read_noise_e))
    return replace(panel, sensor=sensor, fpn=None if panel.fpn is None else cap.fpn,
                   defects=None if panel.defects is None else cap.defects, maps="crop")


def crop_values(cap: CaptureDraw) -> list:
    """The crop's drawn values in CROP_KEYS order, then its defect map's and FPN maps' seeds (online.jsonl)."""
    return [float(cap.values[k]) for k in CROP_KEYS] + [int(cap.defects.seed), int(cap.fpn.seed)]
