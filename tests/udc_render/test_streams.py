"""Named random streams (udc_render.streams): independent for every key path, trailing zeros included."""
import numpy as np
import pytest

from udc_render.streams import seed_sequence, stream


def _first(rng) -> np.ndarray:
    return rng.integers(0, 2**63, 4)


def test_a_trailing_zero_key_is_another_stream():
    # the bug this module exists for: default_rng([s, e, 0]) is default_rng([s, e])
    assert np.array_equal(_first(np.random.default_rng([7, 3, 0])), _first(np.random.default_rng([7, 3])))
    assert not np.array_equal(_first(stream(7, 3, 0)), _first(stream(7, 3)))


def test_two_named_streams_differ_and_each_is_repeatable():
    a, b = stream(7, "online", 2, "crop", 0), stream(7, "online", 2, "order")
    assert not np.array_equal(_first(a), _first(b))
    assert np.array_equal(_first(stream(7, "online", 2, "crop", 0)), _first(stream(7, "online", 2, "crop", 0)))
    draws = np.stack([_first(stream(7, "crop", k)) for k in range(64)])
    assert len({tuple(r) for r in draws}) == 64


def test_keys_follow_numpys_own_spawning():
    # SeedSequence(s).spawn(n)[i] is the stream keyed (i,): an independent oracle for the key path
    child = np.random.SeedSequence(11).spawn(3)[2]
    assert np.array_equal(child.generate_state(4), seed_sequence(11, 2).generate_state(4))


def test_a_negative_key_is_refused():
    with pytest.raises(ValueError, match="non-negative"):
        stream(1, -1)
