"""The step's element-wise updates and energy sums as kernels (mca/kernels.py ``half_kick``, ``drift``,
``sum_of_products``) give the bits of the numpy expressions MCADynamics.step used before them."""

import numpy as np
import pytest

from clusterdyn.mca import kernels as K


def _arrays(n, seed):
    rng = np.random.default_rng(seed)
    scale = lambda: 10.0 ** rng.uniform(-6, 6, size=(n, 3))     # noqa: E731  (many magnitudes)
    return rng, [rng.normal(size=(n, 3)) * scale() for _ in range(4)]


@pytest.mark.parametrize("n", [1, 2, 3, 7, 43, 129, 2731, 30001])
def test_sum_of_products_is_numpys_sum(n):
    rng, (a, b, c, _) = _arrays(n, n)
    assert K.sum_of_products(a, b, c) == np.sum((a + b) * c)
    b = -a + rng.normal(size=a.shape) * 1e-12 * np.abs(a)       # cancellation: the order shows
    assert K.sum_of_products(a, b, c) == np.sum((a + b) * c)


@pytest.mark.parametrize("n", [1, 5, 1000])
def test_kick_and_drift_are_numpys_expressions(n):
    rng, (p, w, F, T) = _arrays(n, 7 + n)
    J = 10.0 ** rng.uniform(-3, 3, size=n)
    m = 10.0 ** rng.uniform(-3, 3, size=n)
    h, dt = 0.37e-3, 0.74e-3
    pos = rng.normal(size=(n, 3)) * 1e5
    theta = rng.normal(size=(n, 3))
    p1, w1 = p + h * F, w + h * T / J[:, None]
    dx1, dth1 = dt * (p1 / m[:, None]), dt * w1
    pos1, theta1 = pos + dx1, theta + dth1
    K.half_kick(p, w, F, T, J, h)
    dx, dth = np.empty_like(p), np.empty_like(w)
    K.drift(p, m, w, dt, pos, theta, dx, dth)
    for got, want in ((p, p1), (w, w1), (dx, dx1), (dth, dth1), (pos, pos1), (theta, theta1)):
        np.testing.assert_array_equal(got, want)
