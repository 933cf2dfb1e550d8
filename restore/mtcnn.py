"""MTCNN face detection (Zhang et al., IEEE SPL 2016) with the weights of `facenet-pytorch`.

The P-, R- and O-nets and the cascade re-implement facenet-pytorch 2.6.0 (`models/mtcnn.py`,
`models/utils/detect_face.py`) for one image: image pyramid (scales 12/min_face · 0.709^k while
the short side stays ≥ 12 px), P-net on each scale (threshold 0.6, NMS 0.5 per scale, then 0.7),
box regression and squaring, 24×24 crops for the R-net (0.7, NMS 0.7), 48×48 crops for the O-net
(0.7, five landmarks, NMS 0.7 on intersection over the smaller box). Crops are resized with area
interpolation and scaled (x − 127.5) / 128, as facenet does. torchvision's NMS is replaced by `nms`.

Weights: `facenet_pytorch/data/{pnet,rnet,onet}.pt` (state dicts), located and never imported
(the package needs torchvision).
"""
from __future__ import annotations

import importlib.util
from pathlib import Path

import numpy as np
import torch
from torch import nn
from torch.nn.functional import interpolate

from udc_render.errors import UdcError

INSTALL = "pip install --no-deps facenet-pytorch==2.6.0"


class MTCNNWeightsError(UdcError):
    """The MTCNN weight files are not installed."""


def weights_dir() -> Path:
    """Folder holding pnet.pt, rnet.pt and onet.pt in the installed (never imported) `facenet_pytorch`."""
    spec = importlib.util.find_spec("facenet_pytorch")
    path = Path(spec.submodule_search_locations[0]) / "data" if spec else None
    if path is None or not all((path / f"{n}.pt").is_file() for n in ("pnet", "rnet", "onet")):
        raise MTCNNWeightsError(f"MTCNN weights not found (package facenet-pytorch); install with `{INSTALL}`")
    return path


class PNet(nn.Module):
    """12×12 proposal net, fully convolutional: (box offsets [N, 4, h, w], probabilities [N, 2, h, w])."""

    def __init__(self):
        super().__init__()
        self.conv1, self.prelu1 = nn.Conv2d(3, 10, 3), nn.PReLU(10)
        self.pool1 = nn.MaxPool2d(2, 2, ceil_mode=True)
        self.conv2, self.prelu2 = nn.Conv2d(10, 16, 3), nn.PReLU(16)
        self.conv3, self.prelu3 = nn.Conv2d(16, 32, 3), nn.PReLU(32)
        self.conv4_1, self.conv4_2 = nn.Conv2d(32, 2, 1), nn.Conv2d(32, 4, 1)

    def forward(self, x):
        x = self.pool1(self.prelu1(self.conv1(x)))
        x = self.prelu3(self.conv3(self.prelu2(self.conv2(x))))
        return self.conv4_2(x), torch.softmax(self.conv4_1(x), 1)


class RNet(nn.Module):
    """24×24 refinement net: (box offsets [N, 4], probabilities [N, 2])."""

    def __init__(self):
        super().__init__()
        self.conv1, self.prelu1 = nn.Conv2d(3, 28, 3), nn.PReLU(28)
        self.pool1 = nn.MaxPool2d(3, 2, ceil_mode=True)
        self.conv2, self.prelu2 = nn.Conv2d(28, 48, 3), nn.PReLU(48)
        self.pool2 = nn.MaxPool2d(3, 2, ceil_mode=True)
        self.conv3, self.prelu3 = nn.Conv2d(48, 64, 2), nn.PReLU(64)
        self.dense4, self.prelu4 = nn.Linear(576, 128), nn.PReLU(128)
        self.dense5_1, self.dense5_2 = nn.Linear(128, 2), nn.Linear(128, 4)

    def forward(self, x):
        x = self.pool1(self.prelu1(self.conv1(x)))
        x = self.pool2(self.prelu2(self.conv2(x)))
        x = self.prelu3(self.conv3(x)).permute(0, 3, 2, 1).reshape(x.shape[0], -1)
        x = self.prelu4(self.dense4(x))
        return self.dense5_2(x), torch.softmax(self.dense5_1(x), 1)


class ONet(nn.Module):
    """48×48 output net: (box offsets [N, 4], landmarks [N, 10] (x1..x5, y1..y5), probabilities [N, 2])."""

    def __init__(self):
        super().__init__()
        self.conv1, self.prelu1 = nn.Conv2d(3, 32, 3), nn.PReLU(32)
        self.pool1 = nn.MaxPool2d(3, 2, ceil_mode=True)
        self.conv2, self.prelu2 = nn.Conv2d(32, 64, 3), nn.PReLU(64)
        self.pool2 = nn.MaxPool2d(3, 2, ceil_mode=True)
        self.conv3, self.prelu3 = nn.Conv2d(64, 64, 3), nn.PReLU(64)
        self.pool3 = nn.MaxPool2d(2, 2, ceil_mode=True)
        self.conv4, self.prelu4 = nn.Conv2d(64, 128, 2), nn.PReLU(128)
        self.dense5, self.prelu5 = nn.Linear(1152, 256), nn.PReLU(256)
        self.dense6_1, self.dense6_2, self.dense6_3 = nn.Linear(256, 2), nn.Linear(256, 4), nn.Linear(256, 10)

    def forward(self, x):
        x = self.pool1(self.prelu1(self.conv1(x)))
        x = self.pool2(self.prelu2(self.conv2(x)))
        x = self.pool3(self.prelu3(self.conv3(x)))
        x = self.prelu4(self.conv4(x)).permute(0, 3, 2, 1).reshape(x.shape[0], -1)
        x = self.prelu5(self.dense5(x))
        return self.dense6_2(x), self.dense6_3(x), torch.softmax(self.dense6_1(x), 1)


def nms(boxes: np.ndarray, scores: np.ndarray, threshold: float, method: str = "union",
        inclusive: bool = False) -> np.ndarray:
    """Indices kept by greedy non-maximum suppression, highest score first.

    A box is dropped when its overlap with a kept box exceeds `threshold`: intersection over union
    (`method="union"`, torchvision's `nms`) or over the smaller area (`"min"`). `inclusive` counts
    pixel boxes inclusively (width x2 − x1 + 1), as facenet's numpy NMS does.
    """
    b = np.asarray(boxes, np.float64).reshape(-1, 4)
    one = 1.0 if inclusive else 0.0
    area = (b[:, 2] - b[:, 0] + one) * (b[:, 3] - b[:, 1] + one)
    order = np.argsort(-np.asarray(scores, np.float64), kind="stable")
    keep = []
    while order.size:
        i, rest = order[0], order[1:]
        keep.append(i)
        w = np.maximum(0.0, np.minimum(b[i, 2], b[rest, 2]) - np.maximum(b[i, 0], b[rest, 0]) + one)
        h = np.maximum(0.0, np.minimum(b[i, 3], b[rest, 3]) - np.maximum(b[i, 1], b[rest, 1]) + one)
        inter = w * h
        if method == "min":
            overlap = inter / np.minimum(area[i], area[rest])
        elif method == "union":
            overlap = inter / (area[i] + area[rest] - inter)
        else:
            raise ValueError(f"unknown NMS method {method!r} (union, min)")
        order = rest[overlap <= threshold]
    return np.asarray(keep, dtype=np.int64)


def box_iou(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """[N, M] intersection over union of boxes a [N, 4] and b [M, 4] (x1, y1, x2, y2; continuous)."""
    a, b = np.asarray(a, np.float64).reshape(-1, 4), np.asarray(b, np.float64).reshape(-1, 4)
    w = np.clip(np.minimum(a[:, None, 2], b[None, :, 2]) - np.maximum(a[:, None, 0], b[None, :, 0]), 0, None)
    h = np.clip(np.minimum(a[:, None, 3], b[None, :, 3]) - np.maximum(a[:, None, 1], b[None, :, 1]), 0, None)
    inter = w * h
    area_a = (a[:, 2] - a[:, 0]) * (a[:, 3] - a[:, 1])
    area_b = (b[:, 2] - b[:, 0]) * (b[:, 3] - b[:, 1])
    return inter / (area_a[:, None] + area_b[None, :] - inter)


def recall(detected_boxes: np.ndarray, true_boxes: np.ndarray, iou: float = 0.5) -> tuple[int, int]:
    """(matched, total): true boxes matched one-to-one to detections with IoU ≥ `iou`, pairs taken
    greedily in decreasing IoU."""
    m = box_iou(true_boxes, detected_boxes)
    matched = 0
    while m.size and m.max() >= iou:
        t, d = np.unravel_index(np.argmax(m), m.shape)
        m[t, :], m[:, d] = -1.0, -1.0
        matched += 1
    return matched, int(np.asarray(true_boxes).reshape(-1, 4).shape[0])


def _rerec(boxes: torch.Tensor) -> torch.Tensor:
    """Boxes squared to their longer side about their centres."""
    w, h = boxes[:, 2] - boxes[:, 0], boxes[:, 3] - boxes[:, 1]
    side = torch.maximum(w, h)
    x1, y1 = boxes[:, 0] + (w - side) / 2, boxes[:, 1] + (h - side) / 2
    return torch.stack([x1, y1, x1 + side, y1 + side], 1)


def _bbreg(boxes: torch.Tensor, reg: torch.Tensor) -> torch.Tensor:
    """Boxes moved by the regression offsets, in units of the inclusive width and height."""
    w, h = boxes[:, 2] - boxes[:, 0] + 1, boxes[:, 3] - boxes[:, 1] + 1
    return boxes + reg * torch.stack([w, h, w, h], 1)


class MTCNN:
    """MTCNN face detector; `detect(image)` on one RGB image (module doc for the cascade)."""

    def __init__(self, min_face_px: int = 20, thresholds=(0.6, 0.7, 0.7), factor: float = 0.709,
                 folder: Path | None = None):
        folder = Path(folder) if folder else weights_dir()
        self.pnet, self.rnet, self.onet = PNet(), RNet(), ONet()
        for name in ("pnet", "rnet", "onet"):
            net = getattr(self, name)
            net.load_state_dict(torch.load(folder / f"{name}.pt", weights_only=True), strict=True)
            net.eval()
        self.min_face_px, self.thresholds, self.factor = min_face_px, tuple(thresholds), factor

    @staticmethod
    def _crops(table: np.ndarray, boxes: torch.Tensor, size: int):
        """Crops [K, 3, size, size] of the boxes clipped to the image, area-resized, and the kept indices.

        Area resizing is torch's adaptive average pooling (bins ⌊o n/size⌋ … ⌈(o+1) n/size⌉), summed
        from the summed-area `table` [H + 1, W + 1, 3] for all crops at once."""
        h, w = table.shape[0] - 1, table.shape[1] - 1
        b = boxes.trunc().int().numpy().astype(np.int64)
        x0, y0 = np.maximum(b[:, 0], 1) - 1, np.maximum(b[:, 1], 1) - 1
        x1, y1 = np.minimum(b[:, 2], w), np.minimum(b[:, 3], h)
        ok = np.flatnonzero((y1 > y0) & (x1 > x0))
        o = np.arange(size)

        def bins(start, stop):
            n = (stop - start)[ok, None]
            return start[ok, None] + o * n // size, start[ok, None] + ((o + 1) * n + size - 1) // size

        (ys, ye), (xs, xe) = bins(y0, y1), bins(x0, x1)
        ys, ye, xs, xe = ys[:, :, None], ye[:, :, None], xs[:, None, :], xe[:, None, :]
        sums = table[ye, xe] - table[ys, xe] - table[ye, xs] + table[ys, xs]
        crops = sums / ((ye - ys) * (xe - xs))[..., None]
        scaled = (torch.from_numpy(crops.astype(np.float32)).permute(0, 3, 1, 2) - 127.5) * 0.0078125
        return scaled, torch.from_numpy(ok)

    @torch.no_grad()
    def detect(self, image: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(boxes [N, 4] x1, y1, x2, y2 in pixels, probabilities [N], landmarks [N, 5, 2] (x, y)), most
        probable first, for an RGB image [H, W, 3]: uint8, or float in [0, 1] (clipped, ×255)."""
        a = np.asarray(image)
        if a.ndim != 3 or a.shape[2] != 3:
            raise ValueError(f"MTCNN needs one RGB image [H, W, 3], got shape {a.shape}")
        a = a.astype(np.float32) if a.dtype == np.uint8 else np.clip(a.astype(np.float32), 0, 1) * 255
        img = torch.from_numpy(np.ascontiguousarray(a)).permute(2, 0, 1)[None]
        table = np.zeros((a.shape[0] + 1, a.shape[1] + 1, 3))
        table[1:, 1:] = a.astype(np.float64).cumsum(0).cumsum(1)
        none = (np.zeros((0, 4)), np.zeros(0), np.zeros((0, 5, 2)))
        h, w = a.shape[:2]
        scale, short = 12.0 / self.min_face_px, min(h, w) * 12.0 / self.min_face_px
        found = []
        while short >= 12:
            found.append(self._stage1(img, scale))
            scale, short = scale * self.factor, short * self.factor
        boxes = torch.cat(found) if found else torch.zeros(0, 9)
        boxes = boxes[nms(boxes[:, :4].numpy(), boxes[:, 4].numpy(), 0.7)]
        if not len(boxes):
            return none
        wh = (boxes[:, 2:4] - boxes[:, :2]).repeat(1, 2)
        boxes = _rerec(boxes[:, :4] + boxes[:, 5:] * wh)

        crops, ok = self._crops(table, boxes, 24)
        if not len(ok):
            return none
        reg, prob = self.rnet(crops)
        score = prob[:, 1]
        p = score > self.thresholds[1]
        boxes, score, reg = boxes[ok][p], score[p], reg[p]
        keep = nms(boxes.numpy(), score.numpy(), 0.7)
        boxes = _rerec(_bbreg(boxes[keep], reg[keep]))
        if not len(boxes):
            return none

        crops, ok = self._crops(table, boxes, 48)
        if not len(ok):
            return none
        reg, marks, prob = self.onet(crops)
        score = prob[:, 1]
        p = score > self.thresholds[2]
        boxes, score, reg, marks = boxes[ok][p], score[p], reg[p], marks[p]
        size = boxes[:, 2:4] - boxes[:, :2] + 1
        points = torch.stack([size[:, None, 0] * marks[:, :5] + boxes[:, None, 0] - 1,
                              size[:, None, 1] * marks[:, 5:] + boxes[:, None, 1] - 1], 2)
        boxes = _bbreg(boxes, reg)
        keep = nms(boxes.numpy(), score.numpy(), 0.7, method="min", inclusive=True)
        return (boxes[keep].numpy().astype(np.float64), score[keep].numpy().astype(np.float64),
                points[keep].numpy().astype(np.float64))

    def _stage1(self, img: torch.Tensor, scale: float) -> torch.Tensor:
        """P-net candidates at one pyramid scale after NMS 0.5: [K, 9] (x1, y1, x2, y2, p, 4 offsets)."""
        h, w = img.shape[2:]
        x = interpolate(img, size=(int(h * scale + 1), int(w * scale + 1)), mode="area")
        reg, prob = self.pnet((x - 127.5) * 0.0078125)
        rows, cols = torch.nonzero(prob[0, 1] >= self.thresholds[0], as_tuple=True)
        cell = torch.stack([cols, rows], 1).to(img.dtype)   # 12×12 cells at stride 2 (x, y)
        boxes = torch.cat([((2 * cell + 1) / scale).floor(), ((2 * cell + 12) / scale).floor(),
                           prob[0, 1, rows, cols][:, None], reg[0, :, rows, cols].T], 1)
        return boxes[nms(boxes[:, :4].numpy(), boxes[:, 4].numpy(), 0.5)]
