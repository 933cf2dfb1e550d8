"""restore.studies.dep_misfit: the misfit kernel (an analytic oracle)."""
import numpy as np
import pytest


def test_magnified_kernel_scales_a_gaussian_and_keeps_unit_sum():
    """dep_misfit's kernel misfit: a Gaussian of σ magnified by s has σ·s (second moment), unit sum, and
    s = 1 gives the kernel back exactly."""
    from restore.studies.dep_misfit import magnified_kernel
    c = np.arange(65) - 32
    g = np.exp(-(c[:, None] ** 2 + c[None] ** 2) / (2 * 4.0 ** 2))
    g /= g.sum()
    assert np.array_equal(magnified_kernel(g, 1.0), g)
    for s in (0.9, 1.0 / 1.05, 1.1):
        m = magnified_kernel(g, s)
        sigma = np.sqrt((m * c[None] ** 2).sum())
        assert abs(m.sum() - 1) < 1e-12 and m.min() >= 0 and m[32, 32] == m.max()
        assert abs(sigma - 4.0 * s) < 2e-3 * 4.0
    with pytest.raises(ValueError, match="scale"):
        magnified_kernel(g, 0.0)
