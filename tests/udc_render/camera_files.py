"""Files written as cameras write them, for the fit's readers: a DNG whose raw image is lossless-JPEG (LJ92:
ITU T.81 Annex H, SOF3, predictor 1) in tiles, with a per-site BlackLevel, BlackLevelDeltaH/V, a
LinearizationTable and an ActiveArea smaller than the image, written by hand (a minimal little-endian TIFF
writer: tifffile cannot write JPEG-compressed tiles without imagecodecs); a 16-bit colour PNG (pypng); a
16-bit TIFF (tifffile). The encoder and the writer are this file's own, so the reader is checked against
an oracle the test controls: the stored codes and the tags' values."""
from __future__ import annotations

import struct
from dataclasses import dataclass

import numpy as np

CATEGORY_BITS = 5  # every difference category 0…16 has a 5-bit Huffman code (its own number): a valid table


def lj92_encode(tile: np.ndarray, precision: int = 16) -> bytes:
    """One component of lossless JPEG, predictor 1 (the left neighbour; the first column the one above, the
    first sample 2^(P − 1)), differences modulo 2^16 coded as category + extra bits (T.81 H.1.2.2)."""
    x = np.asarray(tile, np.int64)
    h, w = x.shape
    pred = np.empty_like(x)
    pred[0, 0] = 1 << (precision - 1)
    pred[0, 1:], pred[1:, 0], pred[1:, 1:] = x[0, :-1], x[:-1, 0], x[1:, :-1]
    diff = (x - pred) & 0xFFFF
    diff = np.where(diff >= 32768, diff - 65536, diff)
    bits = []
    for d in diff.ravel().tolist():
        s = 16 if d == -32768 else abs(d).bit_length()
        bits.append(format(s, f"0{CATEGORY_BITS}b"))
        if 0 < s < 16:
            bits.append(format((d if d > 0 else d - 1) & ((1 << s) - 1), f"0{s}b"))
    stream = "".join(bits)
    stream += "1" * (-len(stream) % 8)
    data = bytearray()
    for i in range(0, len(stream), 8):
        data.append(int(stream[i:i + 8], 2))
        if data[-1] == 0xFF:
            data.append(0)  # byte stuffing

    def segment(marker, payload):
        return bytes([0xFF, marker]) + (len(payload) + 2).to_bytes(2, "big") + payload
    counts = bytes(CATEGORY_BITS - 1) + bytes([17]) + bytes(16 - CATEGORY_BITS)
    dht = segment(0xC4, bytes([0]) + counts + bytes(range(17)))
    sof = segment(0xC3, bytes([precision]) + h.to_bytes(2, "big") + w.to_bytes(2, "big") + bytes([1, 1, 0x11, 0]))
    sos = segment(0xDA, bytes([1, 1, 0, 1, 0, 0]))
    return b"\xff\xd8" + dht + sof + sos + bytes(data) + b"\xff\xd9"


TIFF_TYPES = {1: "B", 2: "s", 3: "H", 4: "I", 5: "I", 10: "i"}  # 5, 10: (numerator, denominator) pairs


def _pack(typ: int, values) -> tuple[bytes, int]:
    if typ == 2:
        b = values.encode() + b"\0"
        return b, len(b)
    flat = [v for pair in values for v in pair] if typ in (5, 10) else list(values)
    return struct.pack("<" + TIFF_TYPES[typ] * len(flat), *flat), len(values)


def write_tiff(path, tags: dict, segments: list[bytes], tiled: bool) -> None:
    """One IFD: tags {code: (TIFF type, values)}; the segments' offsets and byte counts are filled in (tiles
    or strips)."""
    tags = dict(tags)
    off_code, count_code = (324, 325) if tiled else (273, 279)
    tags[count_code] = (4, [len(s) for s in segments])
    tags[off_code] = (4, [0] * len(segments))
    n = len(tags)
    base = 8 + 2 + 12 * n + 4
    packed = {c: _pack(*tags[c]) for c in sorted(tags)}
    extra = sum(len(b) + len(b) % 2 for b, _ in packed.values() if len(b) > 4)
    starts = np.cumsum([0] + [len(s) for s in segments[:-1]]) + base + extra
    packed[off_code] = _pack(4, [int(v) for v in starts])
    ifd, blob = bytearray(struct.pack("<H", n)), bytearray()
    for code in sorted(tags):
        b, count = packed[code]
        typ = tags[code][0]
        if len(b) <= 4:
            ifd += struct.pack("<HHI", code, typ, count) + b.ljust(4, b"\0")
        else:
            ifd += struct.pack("<HHII", code, typ, count, base + len(blob))
            blob += b + b"\0" * (len(b) % 2)
    ifd += struct.pack("<I", 0)
    with open(path, "wb") as fh:
        fh.write(b"II*\0" + struct.pack("<I", 8) + ifd + blob + b"".join(segments))


@dataclass(frozen=True)
class CameraDng:
    """What a camera's DNG holds: stored codes [H, W] (the whole image), the 2 × 2 CFA colours (0 R, 1 G,
    2 B) at the ActiveArea's origin, the black level per site [2, 2] at that origin, the row and column
    deltas of the ActiveArea, the LinearizationTable (None: none), WhiteLevel, ActiveArea (top, left, bottom,
    right), the tile (rows, columns; None: one strip per 16 rows, uncompressed)."""
    stored: np.ndarray
    cfa: tuple = (0, 1, 1, 2)
    black: tuple = ((60.0, 64.0), (66.0, 70.0))
    delta_v: np.ndarray | None = None
    delta_h: np.ndarray | None = None
    table: np.ndarray | None = None
    white: int = 65535
    active: tuple | None = None
    tile: tuple | None = (32, 48)

    def area(self) -> tuple:
        return self.active or (0, 0) + self.stored.shape

    def linear(self) -> np.ndarray:
        """The oracle: the ActiveArea's table[stored] − black(site) − ΔH(column) − ΔV(row), float64."""
        y0, x0, y1, x1 = self.area()
        lin = self.stored if self.table is None else self.table[self.stored]
        black = np.tile(_as_written(self.black), ((y1 - y0) // 2 + 1, (x1 - x0) // 2 + 1))[:y1 - y0, :x1 - x0]
        out = lin[y0:y1, x0:x1].astype(np.float64) - black
        if self.delta_h is not None:
            out -= _as_written(self.delta_h)[None, :]
        if self.delta_v is not None:
            out -= _as_written(self.delta_v)[:, None]
        return out


DENOMINATOR = 1000  # the (S)RATIONAL tags' denominator


def _rationals(values) -> list:
    return [(int(round(v * DENOMINATOR)), DENOMINATOR) for v in np.ravel(values)]


def _as_written(values) -> np.ndarray:
    """The values as the rational tags hold them."""
    return np.round(np.asarray(values, np.float64) * DENOMINATOR) / DENOMINATOR


def write_camera_dng(path, dng: CameraDng) -> None:
    """dng as a DNG 1.4 file (module doc): lossless-JPEG tiles, or uncompressed strips when tile is None."""
    h, w = dng.stored.shape
    stored = np.asarray(dng.stored, np.uint16)
    tags = {254: (4, [0]), 256: (4, [w]), 257: (4, [h]), 258: (3, [16]), 262: (3, [32803]), 277: (3, [1]),
            284: (3, [1]), 271: (2, "udc-test"), 272: (2, "camera"), 50708: (2, "udc-test camera"),
            50706: (1, [1, 4, 0, 0]), 50707: (1, [1, 1, 0, 0]), 33421: (3, [2, 2]), 33422: (1, list(dng.cfa)),
            50710: (1, [0, 1, 2]), 50711: (3, [1]), 50713: (3, [2, 2]), 50714: (5, _rationals(dng.black)),
            50717: (4, [dng.white]), 50778: (3, [21]),
            50721: (10, _rationals(np.eye(3)))}
    if dng.table is not None:
        tags[50712] = (3, [int(v) for v in dng.table])
    if dng.active is not None:
        tags[50829] = (4, list(dng.active))
    if dng.delta_h is not None:
        tags[50715] = (10, _rationals(dng.delta_h))
    if dng.delta_v is not None:
        tags[50716] = (10, _rationals(dng.delta_v))
    if dng.tile is None:
        tags.update({259: (3, [1]), 278: (4, [16])})
        segments = [stored[r:r + 16].tobytes() for r in range(0, h, 16)]
    else:
        th, tw = dng.tile
        padded = np.pad(stored, ((0, -h % th), (0, -w % tw)), mode="edge")
        tags.update({259: (3, [7]), 322: (4, [tw]), 323: (4, [th])})
        segments = [lj92_encode(padded[r:r + th, c:c + tw]) for r in range(0, padded.shape[0], th)
                    for c in range(0, padded.shape[1], tw)]
    write_tiff(path, tags, segments, dng.tile is not None)


def companding_table(stored_bits: int = 14, white: int = 65000) -> np.ndarray:
    """A camera's LinearizationTable: the identity up to 2048, then steps growing linearly (a square-law
    compander, as 14-bit stored values on a 16-bit linear range), reaching `white` at the top code."""
    n = 1 << stored_bits
    i = np.arange(n, dtype=np.float64)
    knee = 2048.0
    a = (white - (n - 1)) / (n - 1 - knee) ** 2
    return np.round(i + a * np.clip(i - knee, 0.0, None) ** 2).astype(np.uint16)


def encode_linear(dng: CameraDng, linear: np.ndarray) -> np.ndarray:
    """The stored codes whose table values lie nearest the wanted linear values above black over the
    ActiveArea (linear + black(site) + ΔH + ΔV), the margins at the black level; the same shape as dng.stored."""
    y0, x0, y1, x1 = dng.area()
    want = np.array(linear, np.float64)
    zero = CameraDng(np.zeros_like(dng.stored), dng.cfa, dng.black, dng.delta_v, dng.delta_h, None, dng.white,
                     dng.active, dng.tile)
    want = want - zero.linear()  # + the black of every pixel
    full = np.full(dng.stored.shape, float(np.mean(dng.black)))
    full[y0:y1, x0:x1] = want
    if dng.table is None:
        return np.clip(np.rint(full), 0, 65535).astype(np.uint16)
    table = dng.table.astype(np.float64)
    j = np.clip(np.searchsorted(table, full), 1, table.size - 1)
    nearer = np.abs(table[j - 1] - full) <= np.abs(table[j] - full)
    return np.where(nearer, j - 1, j).astype(np.uint16)
