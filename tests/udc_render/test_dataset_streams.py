"""Random streams of the dataset, the render and the synthesis (issue 45): numpy pads a seed's entropy with zeros
(default_rng([s, e, 0]) is default_rng([s, e])), so a key list whose last key can be 0 may share its stream with
a shorter one. Each fixed site either draws from a named stream (udc_render.streams) or has a last key that cannot
be 0 or collide; these tests hold each site to that."""
import zlib

import numpy as np
import pytest

from udc_render.dataset.plan import Views, render_seed
from udc_render.dataset.randomize import SCHEMA
from udc_render.dataset.randomize.distributions import stream as draw_stream
from udc_render.pipeline import GT_NOISE_STREAM, gt_noise_seed, noise_seed
from udc_render.render.job import pass_seed
from udc_render.streams import stream

# the names randomize's draws key their streams by, beside the distributions' parameters (draws.py)
DRAW_NAMES = ("disorder", "panel", "defect map", "fpn maps")


def first(rng: np.random.Generator) -> tuple:
    return tuple(rng.integers(0, 2 ** 63, 4))


def test_numpy_pads_the_entropy_with_zeros():
    """The premise: a trailing zero key is no key at all for a plain SeedSequence list, but is for a named stream."""
    assert first(np.random.default_rng([5, 3, 0])) == first(np.random.default_rng([5, 3]))
    assert first(stream(5, 3, 0)) != first(stream(5, 3))


def test_randomize_keys_end_in_distinct_nonzero_crcs():
    """Every randomize stream is (seed, crc32(what), index, crc32(name)): nonzero, distinct last words."""
    names = [*SCHEMA, *DRAW_NAMES]
    crcs = [zlib.crc32(n.encode()) for n in names]
    assert min(crcs) > 0 and len(set(crcs)) == len(names)
    assert zlib.crc32(b"panel") != zlib.crc32(b"capture")
    draws = {first(draw_stream(0, what, i, n)) for what in ("panel", "capture") for i in range(3) for n in names}
    assert len(draws) == 2 * 3 * len(names)


def test_every_display_and_the_ground_truth_have_their_own_noise():
    """noise_seed(seed, item, name) ends in crc32(name): nonzero for the names in use, so no capture's stream is
    SeedSequence([seed, item]); two displays and the averaged ground truth draw apart."""
    names = ("glass", "toled", "poled", "random", GT_NOISE_STREAM)
    assert min(zlib.crc32(n.encode()) for n in names) > 0
    for item in (0, 1):
        states = [tuple(noise_seed(0, item, n).generate_state(4)) for n in names]
        assert len(set(states)) == len(names)
        assert tuple(gt_noise_seed(0, item).generate_state(4)) == states[-1]
        assert tuple(np.random.SeedSequence([0, item]).generate_state(4)) not in states


def test_every_render_pass_has_its_own_seed():
    """pass_seed's key (seed, group, pass) ends in 0 at pass 0; with the pilots' (…, 1) no two coincide."""
    seeds = [pass_seed(1, g, p, pilot) for g in range(4) for p in range(8) for pilot in (False, True)]
    assert len(set(seeds)) == len(seeds)


@pytest.mark.parametrize("item", [1, 2, 7])
def test_a_pose_draws_from_its_named_stream_not_the_render_seeds(item):
    """Item i's jitter u is stream(base, 'pose', i).uniform(−1, 1, 6) (Views' rule), a stream of its own: the
    render seed comes from SeedSequence([base, i])."""
    v = Views((0.0, 1.0, 3.0), (0.0, 0.0, -2.0), (0.0, 1.0, 0.0), (0.1, 0.2, 0.3), (0.4, 0.5, 0.0))
    origin, target, _ = v.pose(7, item)
    u = stream(7, "pose", item).uniform(-1.0, 1.0, 6)
    assert origin == pytest.approx(np.add(v.origin_m, u[:3] * v.origin_jitter_m), abs=1e-15)
    assert target == pytest.approx(np.add(v.target_m, u[3:] * v.target_jitter_m), abs=1e-15)
    render = np.random.SeedSequence([7, item])  # render_seed's: its first word is the item's Mitsuba seed
    assert render_seed(7, item) == int(render.generate_state(1)[0])
    assert not np.allclose(u, np.random.default_rng(render).uniform(-1.0, 1.0, 6))
    assert v.pose(7, item) != v.pose(7, item + 1)
