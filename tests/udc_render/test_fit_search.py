"""The opening's search and residual (udc_render.fit.search, refine) on rows made from the stripe's closed form
|c_mn|² = (w h sinc(m w) sinc(n h))² with Gaussian noise: no image, no render. The stripe's twins (widths w and
1 − w, heights h and 1 − h) give every order with m ≠ 0 and n ≠ 0 the same power, so without the zeroth and the
axes' orders the data cannot tell them apart: the search must find all four and report them; with those orders
it must find the truth alone."""
from __future__ import annotations

import numpy as np
import pytest

from udc_render.fit.families import family
from udc_render.fit.refine import alike, field_columns, minima
from udc_render.fit.search import OrderSet, Rows

TRUTH = (0.3, 0.7)
SCALE = 1e6  # the zeroth order's power


def rows_of(index: np.ndarray, seed: int = 0) -> tuple[Rows, OrderSet]:
    """One exposure's rows of the orders `index` [N, 2]: powers SCALE |c|² with read (σ 3) and shot noise
    (1 per unit power), the field's columns at 10 px per order in a 201-px window."""
    m, n = index[:, 0], index[:, 1]
    c2 = (TRUTH[0] * TRUTH[1] * np.sinc(m * TRUTH[0]) * np.sinc(n * TRUTH[1])) ** 2
    var = 9.0 + SCALE * c2
    power = SCALE * c2 + np.sqrt(var) * np.random.default_rng(seed).standard_normal(len(m))
    uniq, inverse = np.unique(index, axis=0, return_inverse=True)
    design = field_columns(index * 10.0 / 100)
    return Rows(index, inverse.ravel(), power, var, np.ones(len(m)), np.full(len(m), 9.0), design,
                np.zeros(len(m))), OrderSet.of(uniq)


def orders(axes: bool) -> np.ndarray:
    m, n = np.meshgrid(np.arange(-6, 7), np.arange(-6, 7), indexing="ij")
    index = np.stack([m.ravel(), n.ravel()], 1)
    return index if axes else index[(index[:, 0] != 0) & (index[:, 1] != 0)]


@pytest.mark.parametrize("axes", [False, True])
def test_the_search_finds_every_minimum_and_reports_those_the_rows_cannot_tell_apart(axes):
    """Without the zeroth and the axes' orders, the best minimum is the truth or a twin (within 3 σ) and the
    three others are reported as fitting alike (Δχ² < 4); with them, the truth alone, nothing alike."""
    fam = family("toled")[0]
    rows, grid = rows_of(orders(axes))
    sols = minima(fam, rows, grid)[0]
    best = min(sols, key=lambda s: s.chi2)
    sig = np.sqrt(np.diag(best.cov))[:2]
    twins = [np.array(TRUTH)] + [np.array(t) for t in fam.twins(np.array(TRUTH))]
    assert any(np.all(np.abs(best.x[:2] - t) < 3 * sig) for t in twins)
    others = alike(sols, best, 2, len(rows.power) - len(best.x))
    if axes:
        assert np.all(np.abs(best.x[:2] - np.array(TRUTH)) < 3 * sig) and others == ()
    else:
        found = [x for x, _ in others]
        assert len(found) == 3 and all(any(np.all(np.abs(x - t) < 0.01) for x in found + [best.x[:2]]) for t in twins)


def test_an_order_the_model_predicts_at_nothing_costs_its_measured_power():
    """The residual (P − M) / √V stays finite where the model is 0 and costs the row what the measurement shows
    above its read noise: a shape that puts a null on a measured order is penalised by that order's SNR (the log
    residual weighted by M / σ gave it 0). V moves with the model: σ² + B (M − P), never below R."""
    rows, _ = rows_of(np.array([[1, 1], [2, 1]]))
    at_zero = rows.variance(np.zeros(2))
    assert np.allclose(at_zero, np.maximum(rows.var - rows.power.clip(0), 9.0))
    assert np.allclose(rows.variance(rows.power), rows.var)
    assert np.all(np.abs(rows.power) / np.sqrt(at_zero) > 20)  # the orders' SNR: each ~ 40 σ of read noise
