"""Least squares by blocks of rows: the whole-matrix answer, in bounded memory."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.signal import lfilter

from sysid_nn._engine import _least_squares as least_squares
from sysid_nn._engine._subspace import (
    _hankel,
    is_stable,
    output_error_model,
    projection,
)
from sysid_nn._kernels._linear import linear_free_run


def _blocks(D, y, size):
    return ((D[s], y[s]) for s in least_squares.row_blocks(len(D), size))


@pytest.mark.parametrize("size", [7, 100, 5000])
def test_blocks_give_the_whole_matrix_solution(size):
    rng = np.random.default_rng(0)
    D = rng.standard_normal((1000, 6))
    y = D @ rng.standard_normal((6, 2)) + 0.1 * rng.standard_normal((1000, 2))
    theta, products = least_squares.solve(_blocks(D, y, size))
    expected = np.linalg.lstsq(D, y, rcond=None)[0]
    np.testing.assert_allclose(theta, expected, rtol=1e-10, atol=1e-12)
    E = y - D @ expected
    np.testing.assert_allclose(products, E.T @ E, rtol=1e-9)


def test_rank_deficient_designs_get_the_minimum_norm_solution():
    rng = np.random.default_rng(1)
    d = rng.standard_normal((500, 2))
    D = np.column_stack([d, d[:, 0] + d[:, 1]])  # the third column adds nothing
    y = d @ [[1.0], [2.0]]
    theta, _ = least_squares.solve(_blocks(D, y, 64))
    expected = np.linalg.lstsq(D, y, rcond=None)[0]
    np.testing.assert_allclose(theta, expected, atol=1e-10)
    assert least_squares.solve(iter(())) == (None, None)
    # A direction 1e-13 of the largest: below lstsq's cutoff for the whole
    # 10^4-row matrix (eps * 10^4), above one for the 3-row factor alone.
    d = rng.standard_normal((10_000, 2))
    D = np.column_stack([d, d[:, 0] + 1e-13 * rng.standard_normal(10_000)])
    y = d @ [[1.0], [2.0]] + 0.01 * rng.standard_normal((10_000, 1))
    theta, _ = least_squares.solve(_blocks(D, y, 4096))
    expected = np.linalg.lstsq(D, y, rcond=None)[0]
    np.testing.assert_allclose(theta, expected, atol=1e-8)


def _whole_projection(y, u, horizon):
    """The oblique projection with its block-Hankel matrices formed whole."""
    cols = len(y) - 2 * horizon + 1
    past = np.vstack([_hankel(u, 0, horizon, cols), _hankel(y, 0, horizon, cols)])
    design = np.vstack([past, _hankel(u, horizon, horizon, cols)])
    future = _hankel(y, horizon, horizon, cols)
    coef = np.linalg.lstsq(design.T, future.T, rcond=None)[0].T
    L_past = coef[:, : past.shape[0]]
    return L_past, np.linalg.svd(L_past @ past, compute_uv=False)


def test_projection_by_blocks_is_the_whole_projection():
    rng = np.random.default_rng(2)
    u = rng.standard_normal((9000, 1))  # three blocks of windows
    y = lfilter([0.0, 0.4, 0.2], [1.0, -1.2, 0.5], u[:, 0])[:, None]
    y = y + 0.01 * rng.standard_normal(y.shape)
    proj = projection([y], [u], 10)
    L_past, sv = _whole_projection(y, u, 10)
    np.testing.assert_allclose(proj.L_past, L_past, rtol=1e-8, atol=1e-10)
    np.testing.assert_allclose(proj.singular_values, sv[: len(proj.singular_values)],
                               rtol=1e-8, atol=1e-10)  # fmt: skip
    # The output-error model from it simulates the system's free run.
    model = output_error_model([y], [u], proj, 2)
    poles = np.sort(np.abs(np.linalg.eigvals(model.A)))
    np.testing.assert_allclose(poles, [np.sqrt(0.5)] * 2, atol=0.01)


def test_a_pole_within_the_margin_of_the_unit_circle_is_not_stable():
    # Which side of the circle such a pole lands on is rounding.
    near = np.diag([1.0 - 1e-12, 0.5])
    assert not is_stable(near)
    assert not is_stable(np.diag([1.0 + 1e-14, 0.5]))
    assert is_stable(np.diag([1.0 - 1e-6, 0.5]))


def test_output_error_blocks_carry_the_states_across_blocks():
    # Noise-free records of three blocks each: the free run of the fitted
    # model reproduces them only if every block starts where the last ended.
    rng = np.random.default_rng(3)
    U = [rng.standard_normal((9000, 1)), rng.standard_normal((5000, 1))]
    Y = [lfilter([0.0, 0.4, 0.2], [1.0, -1.2, 0.5], u[:, 0])[:, None] for u in U]
    model = output_error_model(Y, U, projection(Y, U, 10), 2)
    for y, u, x0 in zip(Y, U, [np.zeros(2)] * 2, strict=True):
        sim = np.empty_like(y)
        linear_free_run(model.A, model.B, model.C, model.c, u, x0, sim)
        assert np.sqrt(np.mean((sim - y) ** 2)) < 1e-6 * y.std()
