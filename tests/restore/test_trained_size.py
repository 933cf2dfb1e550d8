"""The shipped weights (restore/trained) stay bounded: each retrain adds its float16 model.pt files to the
git history (the cpu run's eight, with the two UNet (randomized): 113 MB, about 104 MB packed), so they are replaced
only when RESULTS.md is regenerated, and the folder holds the models and their small records only. The two slots
(restore.studies.budgets.SLOTS) hold the models RESULTS.md describes (named by shipped.json) and those of a run
under way (committed model by model, so that they outlive a session's machine): each slot is capped, and the
shipped one holds a model per row it names and display."""
import subprocess
from pathlib import Path

import pytest

from restore.studies.budgets import DISPLAYS, ROWS, SHIPPED_FILE, SLOTS, TRAINED_DIR, shipped, shipped_folder
from restore.studies.rescore import shipped_models
from udc_render.dataset.bank import BANK_FILE

ROOT = Path(__file__).resolve().parents[2]
# 6 UNets of 17.9 MB (unet, unet_syn, unet_random × 2 displays) and 2 ResNets of 2.8 MB: 113 MB (float16 state
# dicts); 80 MB until the UNet (randomized) row (issue 31) added two UNets
MAX_TOTAL_MB = 120
SMALL = {".json": 64_000, ".csv": 64_000, ".png": 256_000}  # bytes per file beside model.pt
# a UNet (randomized) run's copy of its bank's bank.json (restore.studies.carry.keep) is kept byte for byte: its
# sha256 is the fingerprint train.json names, so it cannot be written smaller. It holds a record per panel, 10-14 kB
# (166 kB and 222 kB for the fifth run's 16-panel T-OLED and P-OLED banks): room for 28 P-OLED panels
BANK_RECORD_BYTES = 400_000


def tracked() -> list[Path]:
    try:
        out = subprocess.run(["git", "ls-files", "restore/trained"], cwd=ROOT, capture_output=True, text=True,
                             check=True)
    except (OSError, subprocess.CalledProcessError):
        pytest.skip("not a git checkout")
    return [ROOT / line for line in out.stdout.splitlines() if (ROOT / line).is_file()]


def test_shipped_weights_are_bounded():
    sizes: dict[str, int] = {}
    for p in tracked():
        rel = p.relative_to(TRAINED_DIR)
        if rel.parts == (SHIPPED_FILE,):
            continue
        sizes[rel.parts[0]] = sizes.get(rel.parts[0], 0) + p.stat().st_size
    assert set(sizes) <= set(SLOTS), \
        f"restore/trained holds {sorted(set(sizes) - set(SLOTS))}; allowed: {sorted(SLOTS)}"
    for folder, total in sizes.items():
        assert total <= MAX_TOTAL_MB * 1e6, f"restore/trained/{folder} holds {total / 1e6:.1f} MB > {MAX_TOTAL_MB} MB"


def test_the_shipped_slot_holds_a_model_per_row_and_display():
    doc = shipped()
    assert doc["slot"] in SLOTS and set(doc["rows"]) <= {row for row, _, _ in ROWS}
    assert {r for r, _ in shipped_models()} == set(doc["rows"])
    assert all((shipped_folder() / f"{row}_{d}" / "model.pt") in tracked() for row in doc["rows"] for d in DISPLAYS)


def allowed_bytes(path: Path) -> int:
    """The largest size a file beside model.pt may have (0: not allowed)."""
    return BANK_RECORD_BYTES if path.name == BANK_FILE else SMALL.get(path.suffix, 0)


def test_only_models_and_small_records_are_shipped():
    bad = [f"{p.relative_to(ROOT)} ({p.stat().st_size} bytes > {allowed_bytes(p)})" for p in tracked()
           if p.name != "model.pt" and p.stat().st_size > allowed_bytes(p)]
    assert not bad, bad
