"""restore.studies.plateau_criteria: where each criterion stops a logged run."""
import pytest

from restore.studies.plateau_criteria import CRITERIA, markdown, stops
from restore.train import LOG_COLUMNS
from udc_render.io.files import csv_text

# validations (every 2 epochs of 75 steps) of the third cpu run's UNet (Syn) P-OLED to epoch 32
SYN_POLED = [21.01, 22.40, 22.63, 22.51, 22.40, 23.53, 23.91, 24.26, 24.58, 25.08, 25.19, 25.27, 25.62, 25.48,
             25.90, 25.44]


def _write_run(folder, psnr):
    folder.mkdir(parents=True)
    log = []
    for i, v in enumerate(psnr):
        log += [{"epoch": 2 * i + 1, "step": 150 * i + 75, "lr": 2e-4, "loss": 0.05, "val_psnr_db": None, "seconds": 1},
                {"epoch": 2 * i + 2, "step": 150 * i + 150, "lr": 2e-4, "loss": 0.05, "val_psnr_db": v, "seconds": 2}]
    (folder / "loss.csv").write_text(csv_text(log, LOG_COLUMNS))


def test_the_old_criterion_stopped_the_rising_syn_poled_unet_and_todays_does_not(tmp_path):
    _write_run(tmp_path / "unet_syn_poled", SYN_POLED)
    old, new = CRITERIA
    r = stops(tmp_path / "unet_syn_poled" / "loss.csv")
    assert r[old] == (32, 25.44) and r[new] is None and r["end"] == (32, 25.44)
    # the two-fifths line's rise per fifth: 0.3097 dB from these values rounded to 0.01 dB (0.313 from the
    # unrounded log, README)
    assert r["trend_db"] == pytest.approx(0.3097, abs=1e-4)
    table = markdown(tmp_path).splitlines()
    assert table[2] == "| unet_syn_poled | epoch 32, 25.44 dB | — | epoch 32, 25.44 dB | +0.31 |"


def test_a_folder_without_runs_is_a_one_line_error(tmp_path):
    with pytest.raises(ValueError, match="no run folder with a loss.csv"):
        markdown(tmp_path)
