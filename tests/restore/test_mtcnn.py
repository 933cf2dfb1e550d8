"""MTCNN face detection (restore.mtcnn): the astronaut's face, empty and blurred images, NMS, recall."""
from __future__ import annotations

import importlib.util

import numpy as np
import pytest
import torch
from scipy.ndimage import gaussian_filter
from skimage import data

from restore.mtcnn import INSTALL, MTCNN, MTCNNWeightsError, box_iou, nms, recall, weights_dir

torch.set_num_threads(2)

# checked by eye on an overlay: her face from the hairline to the chin; eyes, nose tip, mouth corners
FACE_BOX = (181, 62, 268, 172)
LANDMARKS = [(205, 102), (247, 104), (225, 129), (202, 139), (245, 142)]


@pytest.fixture(scope="module")
def detector():
    return MTCNN()


@pytest.fixture(scope="module")
def astronaut(detector):
    """(image, detections) of skimage's astronaut."""
    img = data.astronaut()
    return img, detector.detect(img)


def test_astronaut_face(astronaut):
    boxes, probs, marks = astronaut[1]
    assert boxes.shape == (1, 4) and probs.shape == (1,) and marks.shape == (1, 5, 2)
    assert probs[0] > 0.99                                       # measured 1.000
    assert box_iou(boxes, [FACE_BOX])[0, 0] > 0.9
    assert np.abs(marks[0] - LANDMARKS).max() < 4


def test_float_input_is_scaled_by_255(detector, astronaut):
    img, (b8, p8, _) = astronaut
    bf, pf, _ = detector.detect(img / 255.0)
    assert np.allclose(bf, b8, atol=1e-3) and np.allclose(pf, p8, atol=1e-6)


def test_flat_and_tiny_images_give_nothing(detector):
    for img in (np.full((256, 320, 3), 128, np.uint8), np.zeros((10, 10, 3), np.uint8)):
        boxes, probs, marks = detector.detect(img)
        assert boxes.shape == (0, 4) and probs.shape == (0,) and marks.shape == (0, 5, 2)


def test_blur_lowers_the_probability(detector, astronaut):
    img, (_, probs, _) = astronaut
    clean = probs.max()
    blurred = detector.detect(gaussian_filter(img / 255.0, (8, 8, 0)))[1]
    assert len(blurred) == 1 and blurred[0] < clean and blurred[0] < 0.95   # measured 0.81


def brute_nms(boxes, scores, threshold, method, inclusive):
    """Greedy NMS written out pair by pair."""
    one = 1.0 if inclusive else 0.0
    order = sorted(range(len(scores)), key=lambda i: -scores[i])
    keep, dropped = [], set()
    for i in order:
        if i in dropped:
            continue
        keep.append(i)
        for j in order:
            if j in dropped or j in keep:
                continue
            ix = max(0.0, min(boxes[i][2], boxes[j][2]) - max(boxes[i][0], boxes[j][0]) + one)
            iy = max(0.0, min(boxes[i][3], boxes[j][3]) - max(boxes[i][1], boxes[j][1]) + one)
            ai = (boxes[i][2] - boxes[i][0] + one) * (boxes[i][3] - boxes[i][1] + one)
            aj = (boxes[j][2] - boxes[j][0] + one) * (boxes[j][3] - boxes[j][1] + one)
            inter = ix * iy
            overlap = inter / min(ai, aj) if method == "min" else inter / (ai + aj - inter)
            if overlap > threshold:
                dropped.add(j)
    return keep


@pytest.mark.parametrize("method,inclusive", [("union", False), ("min", True), ("union", True)])
def test_nms_matches_brute_force(method, inclusive):
    rng = np.random.default_rng(7)
    for _ in range(20):
        xy = rng.uniform(0, 100, (60, 2))
        boxes = np.hstack([xy, xy + rng.uniform(5, 40, (60, 2))])
        scores = rng.permutation(60) / 60.0
        for thr in (0.3, 0.5, 0.7):
            assert nms(boxes, scores, thr, method, inclusive).tolist() == brute_nms(
                boxes.tolist(), scores.tolist(), thr, method, inclusive)
    assert nms(np.zeros((0, 4)), np.zeros(0), 0.5).shape == (0,)


def test_box_iou_and_recall():
    true = np.array([[0, 0, 10, 10], [20, 0, 30, 10], [40, 0, 50, 10]], float)
    assert box_iou(true[:1], [[5, 0, 15, 10]])[0, 0] == pytest.approx(1 / 3)
    det = np.array([[0, 0, 10, 10], [1, 0, 10, 10],           # two detections on the first face
                    [22, 0, 32, 10],                           # IoU 8/12 with the second
                    [45, 0, 55, 10]], float)                   # IoU 1/3 with the third
    assert recall(det, true) == (2, 3)
    assert recall(det, true, iou=0.7) == (1, 3)
    assert recall(det, true, iou=0.3) == (3, 3)
    assert recall(np.zeros((0, 4)), true) == (0, 3)
    # one-to-one: a single detection between two faces matches one of them
    assert recall([[5, 0, 25, 10]], [[0, 0, 20, 10], [10, 0, 30, 10]], iou=0.5) == (1, 2)


def test_missing_weights_name_the_install_command(monkeypatch):
    assert (weights_dir() / "onet.pt").is_file()
    monkeypatch.setattr(importlib.util, "find_spec", lambda name: None)
    with pytest.raises(MTCNNWeightsError, match="facenet-pytorch==2.6.0") as err:
        MTCNN()
    assert INSTALL in str(err.value)
