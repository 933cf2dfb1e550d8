"""Named random streams: one generator per (seed, key, key, …), independent of every other key path.

    rng = stream(seed, "online", epoch, "crop", k)

numpy pads a seed's entropy with zeros, so ``default_rng([seed, epoch, 0])`` is the same stream as
``default_rng([seed, epoch])``: a crop numbered 0 would share the epoch's own stream. Here the keys go into
``SeedSequence(seed, spawn_key=keys)``, whose spawn key is hashed with its length (numpy's own spawning:
``SeedSequence(s).spawn(n)[i]`` is ``SeedSequence(s, spawn_key=(i,))``), so (epoch,) and (epoch, 0) differ.
Strings enter by their CRC-32, so a stream is named by what it draws and not by its position in a list.
"""
from __future__ import annotations

import zlib

import numpy as np

__all__ = ["seed_sequence", "stream", "key_of"]


def key_of(key: int | str) -> int:
    """A spawn-key word: a non-negative integer as it is, a string by its CRC-32."""
    if isinstance(key, str):
        return zlib.crc32(key.encode())
    k = int(key)
    if k < 0:
        raise ValueError(f"stream key {key!r}: expected a non-negative integer or a string")
    return k


def seed_sequence(seed: int, *keys: int | str) -> np.random.SeedSequence:
    """SeedSequence(seed, spawn_key=keys): the stream named by keys under seed."""
    return np.random.SeedSequence(int(seed), spawn_key=tuple(key_of(k) for k in keys))


def stream(seed: int, *keys: int | str) -> np.random.Generator:
    """A numpy Generator on seed_sequence(seed, *keys)."""
    return np.random.default_rng(seed_sequence(seed, *keys))
