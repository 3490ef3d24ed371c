"""Multiple shooting with fitted segment states (``shooting="free"``)."""

import warnings

import numpy as np
import pytest
from scipy.signal import lfilter
from sklearn.exceptions import ConvergenceWarning

from sysid_nn import TDLRegressor
from sysid_nn._engine._shooting import _FreeStateObjective, _segment
from sysid_nn._engine._state_estimation import lowpass, noise_band


def _system(n, seed):
    # A lightly damped second-order system at about 60 samples per period.
    u = np.random.default_rng(seed).standard_normal((n, 1))
    return u, lfilter([0.0, 1e-3], [1.0, -1.98, 0.9891], u[:, 0])


def _net(**params):
    defaults = dict(output_lags=2, input_lags=2, hidden_layer_sizes=(3,))
    defaults.update(n_init=1, random_state=0)
    defaults.update(params)
    return TDLRegressor(**defaults)


def _objective(seg_len=40, alpha=0.0):
    u, y = _system(300, 0)
    est = _net(max_iter=3, alpha=alpha, shooting="measured", early_stopping=False)
    est.fit(u, y)
    train = est._stack([u], [y[:, None]])
    n_res = len(train.modelled)
    mask = est._penalty_mask()
    obj = _FreeStateObjective(est, train, seg_len, mask, n_res, est.output_lags_)
    theta = obj.start(est.coefs_)
    # Move the states off the measured values, so that nothing is zero.
    theta[obj.n_w :] += 0.05 * np.random.default_rng(1).standard_normal(
        len(theta) - obj.n_w
    )
    return obj, theta, train


def test_segments_cover_the_modelled_rows_in_order():
    _, _, train = _objective()
    # 300 modelled rows: a remainder of half a segment or more stands alone,
    # a shorter one joins the last segment.
    lengths = np.diff(_segment(train, 70, 1).data.starts) - train.h
    assert lengths.tolist() == [70, 70, 70, 90]
    segments = _segment(train, 40, 1)
    lengths = np.diff(segments.data.starts) - train.h
    assert lengths.tolist() == [40] * 7 + [20]
    np.testing.assert_array_equal(
        segments.data.Y[segments.data.modelled], train.Y[train.modelled]
    )
    # Each segment's history rows are the rows before it in the record.
    first = segments.first[1]
    np.testing.assert_array_equal(
        segments.data.Y[first - train.h : first], train.Y[40 : 40 + train.h]
    )


@pytest.mark.parametrize("alpha", [0.0, 1e-2])
def test_normal_equations_match_finite_differences_of_the_residuals(alpha):
    obj, theta, _ = _objective(alpha=alpha)
    (A_ww, B, D), g = obj.normal_equations(theta)
    r = obj.residuals(theta)
    # Central differences of the residuals in every parameter.
    J = np.empty((len(r), len(theta)))
    for j in range(len(theta)):
        e = np.zeros_like(theta)
        e[j] = 1e-6
        J[:, j] = (obj.residuals(theta + e) - obj.residuals(theta - e)) / 2e-6
    P, m = obj.n_w, obj.m
    np.testing.assert_allclose(g, J.T @ r, rtol=1e-4, atol=1e-9)
    N = J.T @ J
    # Differences are good to about 1e-6 of the largest entry.
    tol = dict(rtol=1e-4, atol=1e-6 * np.abs(N).max())
    np.testing.assert_allclose(A_ww, N[:P, :P], **tol)
    for s in range(obj.n_seg):
        cols = slice(P + s * m, P + (s + 1) * m)
        np.testing.assert_allclose(B[s], N[:P, cols], **tol)
        np.testing.assert_allclose(D[s], N[cols, cols], **tol)
    # Segments are independent: no coupling between different segments' states.
    np.testing.assert_allclose(N[P : P + m, P + m : P + 2 * m], 0.0, atol=1e-12)


def test_eliminated_step_equals_the_dense_damped_solve():
    obj, theta, _ = _objective()
    (A_ww, B, D), g = obj.normal_equations(theta)
    P, m, S = obj.n_w, obj.m, obj.n_seg
    N = np.zeros((P + S * m, P + S * m))
    N[:P, :P] = A_ww
    for s in range(S):
        cols = slice(P + s * m, P + (s + 1) * m)
        N[:P, cols], N[cols, :P], N[cols, cols] = B[s], B[s].T, D[s]
    for mu in (1e-4, 1.0):
        step, d = obj.damped_step((A_ww, B, D), g, mu)
        np.testing.assert_allclose(d, np.maximum(np.diag(N), 1e-12 * np.diag(N).max()))
        dense = -np.linalg.solve(N + mu * np.diag(d), g)
        np.testing.assert_allclose(step, dense, rtol=1e-7, atol=1e-10)


def test_noise_band_finds_where_the_outputs_clear_the_noise():
    rng = np.random.default_rng(0)
    t = np.arange(4096)
    # Power between 0 and 0.02 cycles per sample, then white noise.
    slow = lfilter(*_butter_low(0.02), rng.standard_normal(len(t)))
    slow /= slow.std()
    noisy = slow + 0.01 * rng.standard_normal(len(t))
    starts = np.array([0, len(t)])
    edge = noise_band(noisy[:, None], starts, 0, np.array([1e-4]))
    assert 0.02 < edge < 0.1
    # Clean records keep their whole band and are left as they are.
    assert noise_band(slow[:, None], starts, 0, np.array([0.0])) == 0.5
    U = rng.standard_normal((len(t), 1))
    Y, U2 = lowpass(noisy[:, None], U, starts, 0, 0.5)
    np.testing.assert_array_equal(Y[:, 0], noisy)
    np.testing.assert_array_equal(U2, U)
    # Low-passed at the band edge, the noise falls and the signal stays.
    Y, _ = lowpass(noisy[:, None], U, starts, 0, edge)
    assert np.std(Y[:, 0] - slow) < 0.75 * np.std(noisy - slow)


def _butter_low(edge):
    from scipy.signal import butter

    return butter(4, edge / 0.5)


def test_auto_shooting_follows_the_noise_and_the_solver():
    u, y = _system(1500, 0)
    noisy = y + 0.01 * y.std() * np.random.default_rng(1).standard_normal(len(y))
    clean = _net(max_iter=2).fit(u, y)
    assert (clean.shooting_, clean.alpha_) == ("measured", 0.0)
    with warnings.catch_warnings():
        warnings.simplefilter("error", UserWarning)  # handled: no noise warning
        warnings.simplefilter("ignore", ConvergenceWarning)
        # Two steps of training: the linear model may win.
        warnings.filterwarnings("ignore", "The linear model of", UserWarning)
        free = _net(max_iter=2).fit(u, noisy)
        assert (free.shooting_, free.alpha_) == ("free", 0.03)
        assert _net(max_iter=2, alpha=0.5).fit(u, noisy).alpha_ == 0.5
    lbfgs = _net(max_iter=2, solver="lbfgs")
    with pytest.warns(UserWarning, match="shooting='auto' or 'free'"):
        assert lbfgs.fit(u, noisy).shooting_ == "measured"
    with pytest.raises(ValueError, match=r"shooting='free' .* needs solver='lm'"):
        _net(max_iter=2, shooting="free", solver="lbfgs").fit(u, y)
    with warnings.catch_warnings():
        warnings.filterwarnings("ignore", "The linear model of", UserWarning)
        forced = _net(max_iter=2, shooting="free").fit(u, y)
    assert forced.shooting_ == "free"
    assert forced._smooth_train is None  # the low-passed copy is not kept


def test_free_shooting_stays_accurate_under_output_noise():
    # With the measured outputs as regressors and restarts (shooting=
    # "measured") this network simulates the clean test record to 0.035
    # NRMSE from 3 % noise; with fitted segment states to 0.006.
    u, y = _system(3000, 0)
    ut, yt = _system(2000, 1)
    rng = np.random.default_rng(2)
    noisy = y + 0.03 * y.std() * rng.standard_normal(len(y))
    with warnings.catch_warnings():
        # The linear model, trained by the same free-state schedule, fits
        # the training record marginally better than the network and may be
        # returned (measured: test 0.0035 against the network's 0.0038).
        warnings.filterwarnings("ignore", "The linear model of", UserWarning)
        est = _net(hidden_layer_sizes=(5,), max_iter=60).fit(u, noisy)
    assert est.shooting_ == "free"
    nrmse = np.sqrt(np.mean((est.simulate(ut) - yt) ** 2)) / yt.std()
    assert nrmse < 0.015


def test_auto_keeps_the_one_step_schedule_on_a_coarse_nonlinear_record():
    # Noise-free, but no linear model explains it: the noise estimate (28 %
    # of the spread) is misfit, which the one-step schedule handles.
    u = np.random.default_rng(1).standard_normal((1500, 1))
    y = np.zeros(len(u))
    for t in range(2, len(u)):
        y[t] = 0.6 * y[t - 1] - 0.1 * y[t - 2] + 0.8 * np.tanh(u[t - 1, 0])
        y[t] += 0.2 * u[t - 2, 0] ** 2
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ConvergenceWarning)
        warnings.simplefilter("ignore", UserWarning)  # the noise warning
        est = _net(max_iter=2).fit(u, y)
    assert est.output_noise_std_[0] > 0.1 * y.std()
    assert (est.shooting_, est.alpha_) == ("measured", 0.0)
