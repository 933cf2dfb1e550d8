"""restore.studies.random_row: the UNet (randomized) row's draws keep the display's family and the documented
ranges, and its training settings point at the bank."""
from types import SimpleNamespace

import pytest

from restore.studies.random_row import family_distributions, online_settings
from restore.train import TrainSettings
from udc_render.dataset.randomize import default_distributions, draw_panels


@pytest.mark.parametrize("family", ["toled", "poled"])
def test_the_family_is_fixed_and_the_other_ranges_kept(family):
    dists = family_distributions(family)
    panels = draw_panels(dists, 24, 0)
    assert {p.family for p in panels} == {family}
    assert len({round(p.values["display.distance_mm"], 6) for p in panels}) == 24  # d still drawn
    assert all(0.5 <= p.values["display.distance_mm"] <= 5.0 for p in panels)
    default = default_distributions().dists
    assert {k: v for k, v in dists.dists.items() if k != "display.family"} == \
        {k: v for k, v in default.items() if k != "display.family"}


def test_online_settings_name_the_banks_panels():
    bank = SimpleNamespace(panels=[SimpleNamespace(name="random_000"), SimpleNamespace(name="random_001")],
                           fingerprint="abc123")
    s = online_settings(TrainSettings(model={"type": "unet", "width": 8}, display="poled", epochs=3), bank)
    assert s.display == "random_000,random_001" and s.epochs == 3
    assert s.degrade == {"mode": "online", "bank_fingerprint": "abc123", "panels": ["random_000", "random_001"]}
