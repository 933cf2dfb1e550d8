"""Face chart (restore.faces): determinism, box layout, and MTCNN's recall on the clean chart."""
from __future__ import annotations

import numpy as np
import pytest
import torch

from restore.mtcnn import MTCNN, box_iou, recall
from restore.studies.face_chart import STUDY_FACE_PX, face_chart

torch.set_num_threads(2)


def test_deterministic_for_a_seed():
    a, ba = face_chart(800, 600, seed=3)
    b, bb = face_chart(800, 600, seed=3)
    c, bc = face_chart(800, 600, seed=4)
    assert a.dtype == np.uint8 and a.shape == (600, 800, 3)
    assert np.array_equal(a, b) and np.array_equal(ba, bb)
    assert not np.array_equal(a, c) and not np.array_equal(ba, bc)


@pytest.mark.parametrize("background", ["texture", "grey"])
def test_boxes_inside_and_apart(background):
    img, boxes = face_chart(1000, 650, seed=1, background=background)
    assert boxes.shape == (5 * 3, 4)
    assert (boxes[:, :2] >= 0).all() and (boxes[:, 2] <= 1000).all() and (boxes[:, 3] <= 650).all()
    side = boxes[:, 3] - boxes[:, 1]
    lo, hi = STUDY_FACE_PX
    assert (side >= 0.96 * lo - 1e-9).all() and (side <= 0.96 * hi + 1e-9).all()
    iou = box_iou(boxes, boxes)
    assert np.allclose(iou, np.eye(len(boxes)))


def test_rejects_bad_arguments():
    with pytest.raises(ValueError, match="at least"):
        face_chart(150, 600)
    with pytest.raises(ValueError, match="face_px"):
        face_chart(face_px=(60, 190))
    with pytest.raises(ValueError, match="background"):
        face_chart(800, 600, background="brick")
    with pytest.raises(ValueError, match="contrast"):
        face_chart(800, 600, contrast=(0.0, 1.0))


def test_mtcnn_recall_on_the_clean_easy_chart():
    img, boxes = face_chart(face_px=(60, 160), contrast=(1.0, 1.0))  # 1920 × 1080, 45 faces
    found, probs, _ = MTCNN().detect(img)
    matched, total = recall(found, boxes, iou=0.5)
    # measured 45 / 45 (seeds 0–3, texture and grey: 44–45 / 45; mean IoU 0.85–0.88)
    assert total == 45 and matched >= 43
    assert len(found) <= 47                      # measured 45 detections, no false positive


def test_the_study_chart_is_hard_even_clean():
    """Faces from 12 to 140 px at contrasts 0.05–1: MTCNN misses some on the chart itself, as the paper's
    clean capture (60 %). Measured 0.62–0.73 over seeds 0–3; the bounds were set after seeing them."""
    img, boxes = face_chart(seed=0)
    found, _, _ = MTCNN().detect(img)
    matched, total = recall(found, boxes, iou=0.5)
    assert 0.4 <= matched / total <= 0.9
