"""sensor.readout: the one sensor model that the numpy synthesis and the online degradation in torch share.

Oracles: hand-computed DN of the formulas (rounding half to even, the full-well cap, the defect levels), and
the same call on numpy and torch arrays (float64) giving the same bits; restore imports the sensor only through
udc_render.sensor's public names.
"""
from __future__ import annotations

import ast
from pathlib import Path

import numpy as np
import torch

import udc_render.sensor as sensor_pkg
from udc_render.sensor import readout

ROOT = Path(__file__).resolve().parents[2]


def test_hand_computed_read_outs():
    """DN of each model on a few pixels, worked by hand: g = 2 DN/e⁻, black 64, FW 100 e⁻, white 250 DN."""
    shot, normal, off = np.array([10.0, 120.0, 40.0]), np.array([0.5, 0.0, -1.0]), np.array([1.0, 0.0, 0.25])
    # poisson: 64 + 2 · min(n + 4 N + o, 100) = 64 + 2 · (13, 100, 36.25)
    np.testing.assert_array_equal(readout.read_poisson(shot, normal, 4.0, off, 100.0, 2.0, 64.0), [90, 264, 136.5])
    np.testing.assert_array_equal(readout.quantised(np.array([90, 264, 136.5, 2.5, -3.0]), 250), [90, 250, 136, 2, 0])
    # gaussian: R = 200, w = min(2 q / 200, cap); y = w + N √(0.01 + 0.04 w); 64 + 200 · min(y, 1)
    q = np.array([50.0, 500.0])
    y = readout.read_gaussian(q, np.array([1.0, 0.0]), 0.01, 0.04, None, 2.0, 200.0, 100.0, 64.0, cap=3.0)
    np.testing.assert_allclose(y, [64 + 200 * (0.5 + np.sqrt(0.01 + 0.02)), 264], rtol=1e-15)
    assert readout.read_noiseless(np.array([30.0]), np.array([-5.0]), 100.0, 2.0, 64.0)[0] == 114
    # defects: dead → black 64; hot + 30 DN capped at 200; a good pixel kept
    dn = readout.with_defects(np.array([100.0, 100.0, 180.0, 100.0]), np.array([readout.DEAD, readout.HOT,
                                                                                 readout.HOT, 0]), 64, 30.0, 200.0, 250)
    np.testing.assert_array_equal(dn, [64, 130, 200, 100])
    np.testing.assert_array_equal(readout.defect_classes(np.array([0.005, 0.01, 0.05, 0.07]), 0.01, 0.05),
                                  [readout.DEAD, readout.HOT, readout.HOT, 0])


def test_numpy_and_torch_give_the_same_bits():
    """float64: every function on torch tensors returns numpy's values bit for bit (the equality of the online
    degradation with the synthesis rests on it), per-crop parameters broadcast as columns; but for Brooks' λ,
    through exp, within 2 ulp."""
    rng = np.random.default_rng(0)
    e = rng.gamma(2.0, 3000.0, (2, 4, 6, 8))
    e[0, 0, 0, 0], e[1, 2, 3, 4] = np.nan, np.inf
    z, u, normal = rng.standard_normal(e.shape), rng.random(e.shape), rng.standard_normal(e.shape)
    col = np.array([1.5, 3.0]).reshape(2, 1, 1, 1)

    def run(xp_e, xp_z, xp_u, xp_n, c):
        q = readout.mean_charge_e(readout.finite_electrons(xp_e), readout.fpn_gain(xp_z, 0.3 * c), 2.0)
        off = readout.fpn_offset_e(xp_u, xp_z[..., :1], xp_u[..., :1, :], c, 0.5, 0.7)
        pois = readout.read_poisson(q, xp_n, 4.87, off, 15506.0, c, 64.0)
        gauss = readout.read_gaussian(q, xp_n, 1e-4 * c, 1e-3, off, c, 65471.0, 15506.0, 64.0, 4.0)
        kind = readout.defect_classes(xp_u, 0.1, 0.2)
        dn = readout.with_defects(readout.quantised(pois, 65535.0), kind, 64.0, 900.0 * c, 60000.0, 65535.0)
        return [q, off, pois, gauss, dn], readout.brooks_lambdas(xp_u, xp_z)
    ours, lam = run(e, z, u, normal, col)
    theirs, lam_t = run(*(torch.from_numpy(a) for a in (e, z, u, normal, col)))
    for a, b in zip(ours, theirs):
        np.testing.assert_array_equal(b.numpy(), a)
    for a, b in zip(lam, lam_t):  # exp is not correctly rounded: libm and torch differ by 1 ulp (1.2e-16 measured)
        np.testing.assert_allclose(b.numpy(), a, rtol=4.5e-16, atol=0)


def test_restore_imports_the_sensor_through_its_public_names():
    """restore/ imports from udc_render.sensor (the package, not its modules) only names of its __all__: no
    private constant crosses the packages, and no copy of the model needs one."""
    bad = []
    for path in sorted((ROOT / "restore").rglob("*.py")):
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.ImportFrom) and (node.module or "").startswith("udc_render.sensor"):
                names = [a.name for a in node.names]
                if node.module != "udc_render.sensor" or set(names) - set(sensor_pkg.__all__):
                    bad.append(f"{path.relative_to(ROOT)}: from {node.module} import {', '.join(names)}")
    assert not bad, bad
