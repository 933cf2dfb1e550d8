"""restore.studies.early_training's log: a variant's row is kept under the same fingerprint only (issue 45)."""
import json

import pytest

import restore.studies.early_training as E
from tests.conftest import write_pairs


@pytest.fixture
def fake_psnr(monkeypatch):
    """early_psnr replaced by a row per call, numbered."""
    calls = []

    def early_psnr(data, display, variant, steps, autocast=None):
        calls.append(variant["variant"])
        return {"variant": variant["variant"], "display": display, "steps": steps, "autocast": autocast,
                "val_psnr_db": float(len(calls)), "loss_last75": 0.1, "seconds": 1.0}
    monkeypatch.setattr(E, "early_psnr", early_psnr)
    return calls


def test_another_dataset_or_an_unfingerprinted_row_is_run_again(fake_psnr, tmp_path, capsys):
    one = write_pairs(tmp_path / "one", splits=(("train", 1), ("val", 1)), size_px=(16, 16))
    two = write_pairs(tmp_path / "two", splits=(("train", 2), ("val", 1)), size_px=(16, 16))
    v = [E.parse_variant("unet:128:1e-3"), E.parse_variant("unet:64:1e-3")]
    path = tmp_path / "results.jsonl"
    rows = E.early_rows(one, "blur", v, 5, None, path)
    assert fake_psnr == ["unet:128:1e-3", "unet:64:1e-3"]
    assert E.early_rows(one, "blur", v, 5, None, path) == rows and len(fake_psnr) == 2
    again = E.early_rows(two, "blur", v[:1], 5, None, path)  # another dataset: its row is replaced
    assert fake_psnr[2:] == ["unet:128:1e-3"] and len(again) == 2 and again[0] == rows[1]
    assert "early_training: 1 logged row in" in capsys.readouterr().out
    old = [{k: x for k, x in r.items() if k != "fingerprint"} for r in again]  # the log before fingerprints
    path.write_text("".join(json.dumps(r) + "\n" for r in old))
    E.early_rows(two, "blur", v[:1], 5, None, path)
    assert fake_psnr[3:] == ["unet:128:1e-3"] and "early_training: 1 logged row in" in capsys.readouterr().out
