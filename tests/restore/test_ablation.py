"""The conditioning ablation (restore.studies.ablation): its arms' switches and its mechanics on tiny settings."""
from __future__ import annotations

import json

import numpy as np
import pytest
import torch

from restore.models import build_model
from restore.studies.ablation import BUDGETS, SCORES_FILE, arm_config, run_ablation
from restore.studies.ablation_report import ARMS, choice, summary
from tests.restore.test_models_conditioned import _bank
from udc_render.dataset.bank import read_bank
from udc_render.errors import UdcError


@pytest.fixture(autouse=True)
def one_thread():
    old = torch.get_num_threads()
    torch.set_num_threads(1)  # the study's own setting: 2 threads on 2 shared cores are slower
    yield
    torch.set_num_threads(old)


def test_the_arms_switch_the_conditioning_and_share_the_backbone():
    """unet is the budget's blind UNet; the four conditioned arms are one wiener-unet config but for the two
    switches, and a model built from each has exactly the parts its arm names; wide is the blind twin of their
    backbone (the same encoder widths; the conditioned arm with neither part also takes 4 channels)."""
    b = BUDGETS["cpu"]
    assert arm_config(b, "unet") == {"type": "unet", "width": 8, "depth": 3}
    cfgs = {a: arm_config(b, a) for a in ARMS if a not in ("unet", "wide")}
    assert {(c["wiener"], c["kernel_codes"]) for c in cfgs.values()} == {(False, False), (False, True), (True, False),
                                                                         (True, True)}
    strip = [{k: v for k, v in c.items() if k not in ("wiener", "kernel_codes")} for c in cfgs.values()]
    assert all(c == strip[0] for c in strip) and strip[0]["kernel_px"] == 33 and strip[0]["width"] == 8
    for arm, cfg in cfgs.items():
        m = build_model({**cfg, "fine_extra_width": 0, "width": 2, "code_dim": 4})
        assert (m.wiener is not None, m.codes is not None) == (arm in ("features", "both"), arm in ("codes", "both"))
    wide, level = build_model(arm_config(b, "wide")), build_model(cfgs["level"])  # the same backbone, blind
    assert [c.weight.shape for c in wide.encoder.modules() if isinstance(c, torch.nn.Conv2d)] == \
        [c.weight.shape for c in level.encoder.modules() if isinstance(c, torch.nn.Conv2d)]


def test_the_ablation_trains_scores_and_resumes_each_arm(tmp_path, capsys, monkeypatch):
    """The tiny budget on two given 9-px blur banks: six arms trained the same steps, every held-out panel scored
    for every row (plain and level-matched, finite), the report written; a re-run keeps every score row, and a
    retrained arm's model makes the rows stale. An unknown budget is refused in one line. (The training runs' loss
    plots are left out: 5 matplotlib figures, most of the test's time.)"""
    monkeypatch.setattr("restore.checkpoints.plot_loss", lambda log, path: None)
    banks = {"random": read_bank(_bank(tmp_path / "r", frame_px=(64, 32))),
             "heldout": read_bank(_bank(tmp_path / "h", frame_px=(64, 32)))}
    out = tmp_path / "ablation"
    result = run_ablation(out, "tiny", banks=banks, progress=False)
    assert {a: s["steps"] for a, s in result["train"].items()} == {a: 4 for a in ARMS}
    assert [r["panel"] for r in result["rows"]] == ["soft", "softer"]
    for r in result["rows"]:
        for k in ("input", "dep", *ARMS):
            assert np.isfinite(r[f"psnr_{k}_db"]) and np.isfinite(r[f"psnr_{k}_level_db"])
            assert len(r["per_image_db"][k]) == 2
    doc = json.loads((out / "ablation.json").read_text())
    assert doc["choice"]["chosen"] in ARMS and (out / "ablation.png").stat().st_size > 0
    assert "## Choice" in (out / "ablation.md").read_text()
    logged = (out / SCORES_FILE).read_text()
    run_ablation(out, "tiny", banks=banks, progress=False)
    assert (out / SCORES_FILE).read_text() == logged
    torch.save(torch.load(out / "train" / "codes" / "model.pt", weights_only=False) | {"retrained": True},
               out / "train" / "codes" / "model.pt")
    capsys.readouterr()
    run_ablation(out, "tiny", banks=banks, progress=False)
    assert "2 " in capsys.readouterr().out
    with pytest.raises(UdcError, match="--budget huge: expected one of cpu, tiny"):
        run_ablation(out, "huge")


def test_the_summary_takes_each_group_and_each_arm_against_the_blind_unet():
    """Group means over their panels and arm − unet differences (a hand-made pair of panels)."""
    keys = ("input", "dep", *ARMS)
    rows = [{"family": f, **{f"psnr_{k}_db": v + i for i, k in enumerate(keys)},
             **{f"psnr_{k}_level_db": v + 2 * i for i, k in enumerate(keys)}} for f, v in (("poled", 10.0),
                                                                                          ("toled", 20.0))]
    s = summary(rows)
    assert s["all"]["panels"] == 2 and s["all"]["means"]["unet"] == {"plain": 17.0, "level": 19.0}
    assert s["poled"]["minus_unet"]["both"] == {"plain": 5.0, "level": 10.0}
    c = choice(s, rows)
    assert {k: c[k] for k in ("chosen", "level_pick", "gain_db", "target_met", "runner_up")} == {
        "chosen": "both", "level_pick": "both", "gain_db": {"plain": 5.0, "level": 10.0}, "target_met": True,
        "runner_up": "features"}
    assert c["against_runner_up"]["plain"] == {"mean": 1.0, "sd": 0.0, "min": 1.0, "max": 1.0, "above": 2}
    assert c["against_unet"]["level"]["mean"] == 10.0 and s["all"]["panels_above_unet"]["codes"]["plain"] == 2
    assert c["against_wide"]["plain"]["mean"] == 4.0  # wide is an arm, never the choice


def test_each_arm_sees_only_the_description_its_parts_read():
    """Tiny untrained models: with neither part the output depends on γ alone (other kernels, gain, noise and
    saturation: bit-equal); Wiener features alone see the kernels and noise but not the scalars only the codes read
    (gain, saturation, outside); kernel codes alone (FiLM made non-zero) see the gain."""
    from tests.restore.test_models_conditioned import TINY, _description, _kernels
    torch.manual_seed(0)
    x = torch.rand(1, 4, 16, 16)
    base = _description(_kernels((1.0, 2.0, 3.0)), read=1e-4, shot=1e-3)
    other = {**_description(_kernels((3.0, 3.0, 3.0), 0.45), read=1e-3, shot=1e-2), "gain": torch.full((1,), 8.0),
             "saturation": torch.full((1,), 1.5), "outside": torch.full((1, 3), 0.1)}
    scalars = {**base, "gain": other["gain"], "saturation": other["saturation"], "outside": other["outside"]}
    models = {arm: build_model({**TINY, **s}).eval() for arm, s in
              {"level": {"wiener": False, "kernel_codes": False}, "features": {"kernel_codes": False},
               "codes": {"wiener": False}}.items()}
    for film in models["codes"].film_encoder:
        torch.nn.init.normal_(film.linear.weight, std=0.5)
    with torch.no_grad():
        out = {arm: m(x, base) for arm, m in models.items()}
        assert torch.equal(models["level"](x, other), out["level"])
        assert (models["level"](x, {**base, "gamma": 2 * base["gamma"]}) - out["level"]).abs().max() > 1e-4
        assert torch.equal(models["features"](x, scalars), out["features"])
        assert (models["features"](x, other) - out["features"]).abs().max() > 1e-4
        assert (models["codes"](x, scalars) - out["codes"]).abs().max() > 1e-6


def test_the_robustness_page_states_the_committed_ablations_numbers():
    """docs/studies/robustness.md's ablation table prints, for every row, the committed run's means (ablation.json's
    summary: every held-out panel, the P-OLED and T-OLED draws; plain and level-matched) to 0.01 dB, names the
    chosen arm, and says which arm each seed's report picks (seed_1/ablation.json)."""
    from restore.studies.ablation_report import ROWS
    from tests.docs.examples import ROOT
    doc = json.loads((ROOT / "docs/figures/restore_studies/ablation_cpu/ablation.json").read_text())
    page = (ROOT / "docs/studies/robustness.md").read_text(encoding="utf-8")
    section = page[page.index("## Which conditioning"):]
    rows = {line.split("|")[1].strip(): line for line in section.splitlines() if line.startswith("| ")}
    for key, label in ROWS.items():
        row = rows[label]
        for group in ("all", "poled", "toled"):
            for kind in ("plain", "level"):
                assert f" {doc['summary'][group]['means'][key][kind]:.2f} " in row, (label, group, kind)
    assert f"The chosen design: `{doc['choice']['chosen']}`" in section
    seed_1 = json.loads((ROOT / "docs/figures/restore_studies/ablation_cpu/seed_1/ablation.json").read_text())
    for seed, d in ((0, doc), (1, seed_1)):
        assert f"seed {seed} picks `{d['choice']['chosen']}`" in " ".join(section.split())
