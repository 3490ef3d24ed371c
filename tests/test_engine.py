"""The engine's layout and the outcomes of its training policy.

Each test here guards a decision by what it does to a fit: which records
are trained on, which weights are kept, what the automatic settings read
from the records, that a failed fit changes nothing, and that the package
stays a one-way stack of named parts.
"""

from __future__ import annotations

import ast
import pathlib
import pickle
import warnings
from itertools import pairwise

import numpy as np
import pytest
from scipy.signal import lfilter
from sklearn.exceptions import ConvergenceWarning
from sklearn.metrics import r2_score
from sklearn.model_selection import GridSearchCV, PredefinedSplit

from sysid_nn import (
    DivergenceWarning,
    HystereticOscillator,
    InconsistentVersionWarning,
    ISSMRegressor,
    TDLRegressor,
)
from sysid_nn._engine._state_estimation import _RUN_IN, _SETTLED_TAIL, rest_check

PACKAGE = pathlib.Path(__file__).resolve().parents[1] / "sysid_nn"


# ------------------------------------------------------------------ layout
def _module_name(path: pathlib.Path) -> str:
    parts = path.relative_to(PACKAGE.parent).with_suffix("").parts
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def _import_graph() -> dict[str, set[str]]:
    modules = {_module_name(p): p for p in PACKAGE.rglob("*.py")}
    graph = {}
    for name, path in modules.items():
        deps = set()
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
                targets = [node.module]
                targets += [f"{node.module}.{a.name}" for a in node.names]
            elif isinstance(node, ast.Import):
                targets = [a.name for a in node.names]
            else:
                continue
            deps.update(t for t in targets if t in modules and t != name)
        graph[name] = deps
    return graph


def _cycles(graph: dict[str, set[str]]) -> list[set[str]]:
    """Strongly connected components of more than one module (Tarjan)."""
    index, low, stack, on_stack, found = {}, {}, [], set(), []

    def visit(v):
        index[v] = low[v] = len(index)
        stack.append(v)
        on_stack.add(v)
        for w in graph[v]:
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on_stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            component = set()
            while True:
                w = stack.pop()
                on_stack.discard(w)
                component.add(w)
                if w == v:
                    break
            if len(component) > 1:
                found.append(component)

    for v in graph:
        if v not in index:
            visit(v)
    return found


def test_the_package_imports_one_way():
    # The residual tests draw themselves through a lazy ``.plot()``: the one
    # accepted circle.
    cycles = _cycles(_import_graph())
    assert cycles == [] or cycles == [{"sysid_nn.residuals", "sysid_nn.plotting"}]


#: What each group of private modules may import besides itself: the
#: records at the bottom, the engine above them, the analyses beside it, and
#: the foundation modules (warnings, docstring templates, shared statistics)
#: under all.
_FOUNDATION = {"sysid_nn._exceptions", "sysid_nn._docstrings", "sysid_nn._statistics"}
_GROUPS = {
    "sysid_nn._kernels": set(),
    "sysid_nn._records": {"sysid_nn._kernels"},
    "sysid_nn._engine": {"sysid_nn._kernels", "sysid_nn._records"},
    "sysid_nn._analysis": {"sysid_nn._kernels", "sysid_nn._records"},
    "sysid_nn._estimators": {
        "sysid_nn._kernels",
        "sysid_nn._records",
        "sysid_nn._engine",
        "sysid_nn._analysis",
    },
}


def _group(module: str) -> str:
    return ".".join(module.split(".")[:2])


def _group_violations(graph: dict[str, set[str]]) -> list[tuple[str, str]]:
    bad = []
    for module, deps in graph.items():
        group = _group(module)
        if group in _FOUNDATION:
            allowed = set()
        elif group in _GROUPS:
            allowed = _GROUPS[group] | _FOUNDATION | {group}
        else:
            continue
        bad += [(module, d) for d in sorted(deps) if _group(d) not in allowed]
    return bad


def test_the_groups_import_one_way():
    # The foundation may reach the package's version lazily (``sysid_nn``).
    graph = {m: d - {"sysid_nn"} for m, d in _import_graph().items()}
    assert _group_violations(graph) == []
    # Every private module sits in a group but the foundation, the model
    # files and export (which read estimators of every kind), the kernels'
    # compilation and the old paths' aliases.
    flat = {
        p.stem for p in PACKAGE.glob("_*.py") if p.stem not in {"__init__", "__main__"}
    }
    assert flat == {
        "_compile",
        "_export",
        "_saved",
        "_exceptions",
        "_docstrings",
        "_statistics",
        "_moved",
    }


def test_group_check_finds_an_upward_import():
    graph = {
        "sysid_nn._records._data": {"sysid_nn._engine._training"},
        "sysid_nn._engine._training": {"sysid_nn._records._data"},
        "sysid_nn._analysis._uncertainty": {"sysid_nn._engine._solvers"},
    }
    assert _group_violations(graph) == [
        ("sysid_nn._records._data", "sysid_nn._engine._training"),
        ("sysid_nn._analysis._uncertainty", "sysid_nn._engine._solvers"),
    ]


def test_models_pickled_under_the_old_module_paths_load(tmp_path):
    # A model file written before the private modules moved into groups
    # names its classes by the old paths (protocol 0 keeps them as text).
    X, y = _arx_records(1)
    model = TDLRegressor(hidden_layer_sizes=(2,), n_init=1, max_iter=2)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        model.fit(X, y)
    blob = pickle.dumps(model, protocol=0)
    old = blob
    for group in ("_records", "_engine", "_analysis", "_estimators"):
        old = old.replace(f"sysid_nn.{group}.".encode(), b"sysid_nn.")
    assert old != blob  # the model does refer to moved modules
    loaded = pickle.loads(old)
    np.testing.assert_array_equal(loaded.simulate(X[0]), model.simulate(X[0]))


def test_cycle_finder_finds_a_cycle():
    graph = {"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}
    assert _cycles(graph) == [{"a", "b", "c"}]


def test_no_module_exceeds_a_thousand_lines():
    long = {
        str(p.relative_to(PACKAGE)): n
        for p in PACKAGE.rglob("*.py")
        if (n := len(p.read_text().splitlines())) > 1000
    }
    assert not long, long


# ------------------------------------------------------------------- data
def _oscillator_records(n, dt=0.01, noise=0.0, seed=0, n_samples=500):
    rec = HystereticOscillator(r0=0.05).generate(
        n, n_samples=n_samples, dt=dt, random_state=seed
    )
    rng = np.random.default_rng(seed + 100)
    X = [rec.excitation[i][:, None] for i in range(n)]
    y = []
    for i in range(n):
        yi = rec.displacement[i]
        y.append(yi + noise * yi.std() * rng.standard_normal(len(yi)))
    return X, y


def _arx_records(n, length=200, seed=0):
    """Records of ``y(t) = 1.5 y(t-1) - 0.7 y(t-2) + 0.5 u(t-1)``."""
    rng = np.random.default_rng(seed)
    X = [rng.standard_normal((length, 1)) for _ in range(n)]
    y = [lfilter([0.0, 0.5], [1.0, -1.5, 0.7], x[:, 0]) for x in X]
    return X, y


def _small(**params):
    # The lags of the oscillator (the rule's choice on longer records).
    base = dict(
        output_lags=3,
        input_lags=3,
        hidden_layer_sizes=(3,),
        n_init=2,
        max_iter=8,
        shooting_segments=(20,),
        random_state=0,
    )
    return TDLRegressor(**{**base, **params})


# ------------------------------------------------- what is trained and kept
def test_held_out_records_are_not_trained_on():
    X, y = _oscillator_records(5)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ConvergenceWarning)
        split = _small().fit(X, y)
        explicit = _small().fit(X[:4], y[:4], X_val=X[4:], y_val=y[4:])
    # The internal split holds out the last record: the same fit as passing
    # it as validation data, which is never trained on.
    np.testing.assert_array_equal(split.coefs_, explicit.coefs_)
    np.testing.assert_array_equal(split._y_scale, explicit._y_scale)


def test_kept_weights_are_the_best_seen_on_validation():
    X, y = _oscillator_records(4, seed=1)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ConvergenceWarning)
        model = _small(n_init=3, shooting_segments=(20, 50)).fit(X, y)
    # The three restarts and the refinement of the linear model.
    assert model.n_restarts_ == 4 == len(model.training_history_)
    assert model.refined_restart_ == 3
    assert model.restart_scores_[model.best_restart_] == model.restart_scores_.max()
    chosen = model.training_history_[model.best_restart_]
    seen = [v for stage in chosen for v in stage.validation]
    assert model.best_validation_score_ == pytest.approx(-min(seen), rel=1e-12)
    assert model.validation_scores_ == [-v for v in seen]
    best_stage = chosen[model.best_stage_]
    assert -model.best_validation_score_ in best_stage.validation
    # The loss curve falls within each stage (accepted steps only).
    for stage in chosen:
        assert all(b <= a for a, b in pairwise(stage.loss))
    assert len(model.loss_curve_) == sum(len(stage.loss) for stage in chosen)


def test_grid_search_picks_the_lags_of_the_system():
    # Two output lags generate the records; one cannot fit them. The right
    # candidate is listed second, so a search that cannot tell them apart
    # picks the wrong one.
    X, y = _arx_records(1, length=600)
    X, y = X[0], y[0]
    fold = np.repeat([0, 1], 300)
    search = GridSearchCV(
        TDLRegressor(hidden_layer_sizes=(), input_lags=1, n_init=1, random_state=0),
        {"output_lags": [1, 2]},
        cv=PredefinedSplit(fold),
    )
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ConvergenceWarning)
        search.fit(X, y)
    assert search.best_params_ == {"output_lags": 2}
    assert search.best_score_ > 0.99


def test_fallback_returns_the_linear_start_when_every_restart_diverged(monkeypatch):
    from sysid_nn._engine import _selection

    X, y = _oscillator_records(4, seed=2)
    model = _small()
    # The fallback serves where no trained linear model is a candidate (with
    # one, that model is returned instead: tests/test_selection.py).
    monkeypatch.setattr(_selection, "linear_candidate", lambda *args: None)
    original = model._fit_stages

    def diverging(train, val, restart, stop):
        restart, run = original(train, val, restart, stop)
        run.criterion = np.inf  # as if its free run had diverged on validation
        return restart, run

    model._fit_stages = diverging
    with (
        warnings.catch_warnings(),
        pytest.warns(DivergenceWarning, match="falls back to the linear"),
    ):
        warnings.simplefilter("ignore", ConvergenceWarning)
        model.fit(X, y)
    assert model.fallback_ == "linear_start"
    np.testing.assert_array_equal(
        model.coefs_, model._initial_params(np.random.RandomState(0))
    )
    assert np.all(np.isfinite(model.simulate(X[0])))


# ------------------------------------------------------- automatic settings
@pytest.mark.parametrize("dt", [0.01, 0.02, 0.05])
def test_clean_records_get_no_noise_warning(dt):
    X, y = _oscillator_records(3, dt=dt, seed=3)
    for model in (_small(shooting="measured"), ISSMRegressor(n_init=1, max_iter=5)):
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            model.fit(X, y)
        noise = [w for w in caught if "misfit" in str(w.message)]
        assert noise == [], [str(w.message) for w in noise]
        assert not model.white_misfit_
        assert np.all(model.one_step_misfit_correlation_ > 0.2)


def test_noise_free_nonlinear_autoregression_gets_no_noise_warning():
    # White excitation through a static non-linearity: a white one-step
    # misfit of a linear model, but a function of the regressors.
    rng = np.random.default_rng(4)
    X, y = [], []
    for _ in range(3):
        u = rng.standard_normal(300)
        out = np.zeros(300)
        for t in range(2, 300):
            out[t] = 1.2 * out[t - 1] - 0.5 * out[t - 2] + 0.3 * u[t - 1]
            out[t] += 0.2 * np.tanh(2.0 * out[t - 1])
        X.append(u[:, None])
        y.append(out)
    model = _small(shooting="measured", max_iter=2)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        model.fit(X, y)
    assert not [w for w in caught if "misfit" in str(w.message)]
    assert model.one_step_misfit_share_[0] > 0.02
    assert model.one_step_misfit_explained_[0] > 0.1
    assert not model.white_misfit_


@pytest.mark.filterwarnings("ignore:The linear model of:UserWarning")
def test_noisy_records_are_told_apart_from_unresolved_dynamics():
    # Coarse clean records: a broadband misfit of dynamics the lags do not
    # resolve (smooth), which switches to fitted segment states silently.
    X, y = _oscillator_records(3, dt=0.05, seed=5, n_samples=800)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ConvergenceWarning)
        coarse = _small(n_init=1, shooting_segments=(100,)).fit(X, y)
    assert coarse.one_step_misfit_share_[0] > 0.02
    assert coarse.shooting_ == "free" and not coarse.white_misfit_
    assert coarse.samples_per_period_ == pytest.approx(20, rel=0.3)
    # 1 % white noise at 100 samples per period: noise, and said so.
    X, y = _oscillator_records(3, noise=0.01, seed=5)
    with pytest.warns(UserWarning, match="white misfit .* white measurement noise"):
        noisy = _small(shooting="measured", max_iter=3).fit(X, y)
    assert noisy.white_misfit_
    assert noisy.one_step_misfit_correlation_[0] < 0.2
    assert noisy.one_step_misfit_explained_[0] < 0.1
    np.testing.assert_allclose(noisy.output_noise_std_, 0.01 * np.std(y), rtol=0.3)
    assert 0 < noisy.band_edge_ < 0.5


# ----------------------------------------------------------- atomic fitting
def test_a_rejected_refit_leaves_the_model_as_it_was():
    X, y = _oscillator_records(3, seed=6)
    model = TDLRegressor(n_init=1, max_iter=5, random_state=0)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ConvergenceWarning)
        model.fit(X[:2], y[:2])
    before = model.simulate(X[2])
    state = dict(vars(model))
    with pytest.raises(ValueError, match="cannot be standardised"):
        model.fit(X[0], y[0] * 1e200)
    np.testing.assert_array_equal(model.simulate(X[2]), before)
    assert vars(model).keys() == state.keys()
    assert all(vars(model)[k] is v for k, v in state.items())


def test_an_interrupted_refit_leaves_the_model_as_it_was(monkeypatch):

    X, y = _oscillator_records(3, seed=7)
    model = _small()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ConvergenceWarning)
        model.fit(X[:2], y[:2])
    before = model.simulate(X[2])
    state = dict(vars(model))

    def interrupted(*args, **kwargs):
        raise KeyboardInterrupt

    monkeypatch.setattr(TDLRegressor, "_fit_stages", interrupted)
    with pytest.raises(KeyboardInterrupt):
        model.fit(X[1:], y[1:])
    assert vars(model).keys() == state.keys()
    assert all(vars(model)[k] is v for k, v in state.items())
    np.testing.assert_array_equal(model.simulate(X[2]), before)


@pytest.mark.filterwarnings("ignore:The linear model of:UserWarning")
def test_a_refit_drops_what_the_earlier_fit_kept():
    X, y = _oscillator_records(3, seed=8)
    model = ISSMRegressor(init="tdl", hidden_layer_sizes=(3,), n_init=1, max_iter=3)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ConvergenceWarning)
        model.fit(X, y)
        assert hasattr(model, "tdl_")
        assert model.training_history_ == model.tdl_.training_history_
        assert model.n_restarts_ == len(model.restart_scores_)
        model.set_params(init="arx").fit(X, y)
    assert not hasattr(model, "tdl_")


# ---------------------------------------------------- visible fallbacks
def test_a_skipped_stage_is_warned_about_and_recorded(monkeypatch, capsys):
    from sysid_nn._engine import _solvers

    X, y = _oscillator_records(3, seed=9)
    model = _small(n_init=1, shooting_segments=(20, 50))
    loss = _solvers._Objective.loss

    def non_finite_at_20(self, w):
        return np.inf if self.seg == 20 else loss(self, w)

    monkeypatch.setattr(_solvers._Objective, "loss", non_finite_at_20)
    model.set_params(verbose=1)
    with (
        warnings.catch_warnings(),
        pytest.warns(ConvergenceWarning, match="skipped training stage") as caught,
    ):
        warnings.simplefilter("ignore", DivergenceWarning)
        model.fit(X, y)
    assert model.skipped_stages_ == [1]
    assert model.training_history_[0][1].skipped
    # The warning counts the stage as the progress lines do (from 1).
    message = next(str(w.message) for w in caught if "skipped" in str(w.message))
    n_stages = len(model.training_history_[0])
    assert f"skipped training stage 2 of {n_stages} " in message
    progress = capsys.readouterr().err
    assert f"restart 1/1 stage 2/{n_stages} (segment 20): skipped" in progress


def test_bands_unavailable_are_warned_about_and_recorded(monkeypatch):
    from sysid_nn._analysis import _uncertainty

    X, y = _arx_records(3)
    model = TDLRegressor(hidden_layer_sizes=(), n_init=1, random_state=0)
    monkeypatch.setattr(_uncertainty, "_normal_matrix", lambda *args: None)
    with pytest.warns(UserWarning, match="No confidence or prediction bands"):
        model.fit(X, y)
    assert "diverged" in model.bands_unavailable_
    assert np.all(np.isnan(model.simulate(X[0], return_std=True)[1]))


def test_a_failed_initial_state_fit_warns(monkeypatch):
    from scipy import optimize

    X, y = _arx_records(2)
    model = TDLRegressor(hidden_layer_sizes=(), n_init=1, random_state=0).fit(X, y)
    solve = optimize.least_squares

    def failing(*args, **kwargs):
        result = solve(*args, **kwargs)
        result.success, result.message = False, "gave up"
        return result

    monkeypatch.setattr(optimize, "least_squares", failing)
    with pytest.warns(ConvergenceWarning, match="gave up"):
        model.simulate(X[0], y_init=y[0][:20])


def test_the_initial_state_fit_of_y_init_has_ten_times_the_solver_budget(
    monkeypatch,
):
    # Windows nearly flat along some initial values (many lags of a smooth
    # output) need more than the solver's default 100 evaluations per
    # unknown: the Wiener-Hammerstein TDL's six lags took 1593.
    from scipy import optimize

    X, y = _arx_records(2)
    model = TDLRegressor(hidden_layer_sizes=(), n_init=1, random_state=0).fit(X, y)
    solve, budgets = optimize.least_squares, []

    def spy(fun, x0, **kwargs):
        budgets.append((len(x0), kwargs.get("max_nfev")))
        return solve(fun, x0, **kwargs)

    monkeypatch.setattr(optimize, "least_squares", spy)
    model.simulate(X[0], y_init=y[0][:20])
    (n_unknowns, budget), *_ = budgets
    assert budget == 1000 * n_unknowns


def test_warnings_name_the_line_that_called_the_package():
    # Warnings are raised at different depths below fit and simulate (and
    # the ISSM's TDL start is an estimator fitted inside another); each
    # must name the user's line.
    X, y = _arx_records(2)
    model = ISSMRegressor(hidden_layer_sizes=(3,), n_init=1, max_iter=1, random_state=0)
    linear = TDLRegressor(hidden_layer_sizes=(), n_init=1, random_state=0)
    with warnings.catch_warnings(record=True) as record:
        warnings.simplefilter("always")
        model.fit(X, y)
        linear.fit(X, y).simulate(X[0] * 1e6)
    kinds = {w.category for w in record}
    assert {ConvergenceWarning, DivergenceWarning} <= kinds
    assert {w.filename for w in record} == {__file__}


# ------------------------------------------------------- free runs at rest
@pytest.mark.parametrize(
    "model, zero",
    [
        (
            TDLRegressor(hidden_layer_sizes=(), n_init=1, random_state=0),
            lambda m: {"initial_outputs": np.zeros((m.output_lags_, 1))},
        ),
        (
            ISSMRegressor(
                n_states=2, hidden_layer_sizes=(3,), n_init=1, random_state=0
            ),
            lambda m: {"initial_state": np.zeros(m.n_states_)},
        ),
    ],
)
def test_a_record_at_rest_is_simulated_from_the_models_rest(model, zero):
    # The records sit at an offset: at rest the output is 1, not 0, so the
    # zero start is away from the model's rest by the offset.
    X, y = _arx_records(3, length=300)
    y = [yi + 1.0 for yi in y]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        model.fit(X[:2], y[:2])
    at_rest = model.simulate(X[2])
    from_zero = model.simulate(X[2], **zero(model))
    start = slice(0, 20)
    assert np.max(np.abs(at_rest - y[2])[start]) < 0.05
    assert np.max(np.abs(from_zero - y[2])[start]) > 0.2
    # Under no excitation a model at rest stays there, at rest_output_.
    quiet = model.simulate(np.zeros((100, 1)))
    np.testing.assert_allclose(quiet, quiet[-1], atol=1e-6)
    np.testing.assert_allclose(quiet[-1], model.rest_output_[0], atol=1e-9)
    np.testing.assert_allclose(model.rest_output_, [1.0], atol=0.05)
    check = model.rest_check_
    assert (check.start, check.run_in) == ("rest", _RUN_IN)
    assert check.reason == "settled within the range of the training outputs"
    np.testing.assert_array_equal(check.output, model.rest_output_)
    assert np.all(check.change <= check.tolerance)
    assert check.training_range[0][0] < check.end[0] < check.training_range[1][0]
    # The rest is the end of a run-in over zero excitation from zero.
    lead = np.zeros((_RUN_IN, 1))
    run = model.simulate(np.vstack([lead, X[2]]), **zero(model))
    np.testing.assert_allclose(at_rest, run[_RUN_IN:])
    # Every free run starts there: the model's score and, for the ISSM,
    # its states without measured outputs.
    assert model.score(X[2], y[2]) == pytest.approx(r2_score(y[2], at_rest))
    if isinstance(model, ISSMRegressor):
        states = model.predict_states(X[2]).states
        np.testing.assert_allclose(states[:, 0], at_rest)


def test_a_model_that_does_not_settle_in_range_has_no_rest():
    settled = np.ones((_RUN_IN, 1))
    drifting = np.linspace(0.0, 1.0, _RUN_IN)[:, None]

    def runs(Y, diverged=False):
        def free_run(X):
            assert X.shape == (_RUN_IN, 2) and np.all(X == 0.0)  # zero excitation
            return Y, diverged

        return free_run

    y_range = (-2.0, 2.0)
    np.testing.assert_array_equal(rest_check(runs(settled), 2, y_range).output, [1.0])
    # Still moving (an integrator); diverged; settled outside the training
    # outputs' range: no rest, free runs start from zero.
    assert rest_check(runs(drifting), 2, y_range).output is None
    assert rest_check(runs(settled, diverged=True), 2, y_range).output is None
    assert rest_check(runs(3.0 * settled), 2, y_range).output is None
    # The evidence says which, with the numbers.
    reasons = {
        "still moving": runs(drifting),
        "diverged": runs(settled, diverged=True),
        "outside the range": runs(3.0 * settled),
        "within the range": runs(settled),
    }
    for reason, free_run in reasons.items():
        check = rest_check(free_run, 2, y_range)
        assert reason in check.reason
        assert check.start == ("rest" if reason == "within the range" else "zero")
    moving = rest_check(runs(drifting), 2, y_range)
    assert moving.change[0] == pytest.approx(2047 / (_RUN_IN - 1))
    assert np.isinf(rest_check(runs(settled, diverged=True), 2, y_range).change[0])


def test_a_model_on_a_sustained_cycle_starts_after_the_run_in():
    t = np.arange(_RUN_IN)[:, None]
    cycle = 0.5 + 0.1 * np.sin(0.3 * t)

    def run(Y):
        return lambda X: (Y, False)

    y_range = (-2.0, 2.0)
    check = rest_check(run(cycle), 2, y_range)
    assert (check.start, check.output, check.cycling) == ("cycle", None, True)
    assert "sustained cycle within" in check.reason
    np.testing.assert_allclose(check.end, cycle[-1])
    # Decaying by a quarter over a window, drifting by 15 % of the width over
    # it: no cycle, from zero.
    decaying = 0.5 + 0.1 * np.exp(-1.5e-4 * t) * np.sin(0.3 * t)
    wave = np.sin(0.3 * t)  # its troughs alone decaying: each edge is judged
    one_sided = 0.5 + 0.1 * np.where(wave < 0, 1.0 - t / _RUN_IN, 1.0) * wave
    drifting = cycle + 0.03 * t / _SETTLED_TAIL
    for Y in (decaying, one_sided, drifting):
        check = rest_check(run(Y), 2, y_range)
        assert (check.start, check.output, check.cycling) == ("zero", None, False)
        assert "still moving" in check.reason
    # A cycle reaching outside the training outputs: from zero, but cycling.
    check = rest_check(run(20.0 * cycle), 2, y_range)
    assert (check.start, check.output, check.cycling) == ("zero", None, True)
    assert "sustained cycle beyond" in check.reason
    # Within the tolerance: decaying by 4 % over a window (each edge moves
    # by a fifth of the tolerance).
    slow = 0.5 + 0.1 * np.exp(-2e-5 * t) * np.sin(0.3 * t)
    assert rest_check(run(slow), 2, y_range).start == "cycle"
    # Every output must be on its cycle.
    both = np.column_stack([cycle[:, 0], drifting[:, 0]])
    assert rest_check(run(both), 2, (np.full(2, -2.0), np.full(2, 2.0))).start == "zero"


# ------------------------------------------------------ observable weights
@pytest.mark.parametrize(
    "model",
    [
        TDLRegressor(hidden_layer_sizes=(4, 3), n_init=1, max_iter=3),
        ISSMRegressor(hidden_layer_sizes=(4,), n_init=1, max_iter=3),
    ],
)
def test_weight_views_are_the_flat_vector(model):
    X, y = _arx_records(2)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ConvergenceWarning)
        model.fit(X, y)
    coefs, intercepts = model.layer_coefs_, model.layer_intercepts_
    n_in = model._sizes_[0]
    assert coefs[0].shape[0] == n_in and coefs[-1].shape[1] == model._sizes_[-1]
    for a, b in pairwise(coefs):
        assert a.shape[1] == b.shape[0]
    flat = [np.r_[W.T.ravel(), b] for W, b in zip(coefs, intercepts, strict=True)]
    flat.append(model.linear_coef_.ravel())
    np.testing.assert_array_equal(np.concatenate(flat), model.coefs_)


# ----------------------------------------------------------- version stamp
def test_unpickling_a_model_of_another_version_warns():
    X, y = _arx_records(2)
    model = TDLRegressor(hidden_layer_sizes=(), n_init=1, random_state=0).fit(X, y)
    with warnings.catch_warnings():
        warnings.simplefilter("error", InconsistentVersionWarning)
        same = pickle.loads(pickle.dumps(model))
    np.testing.assert_array_equal(same.coefs_, model.coefs_)
    model._sysid_nn_version = "0.0.1"
    with pytest.warns(InconsistentVersionWarning, match="version 0.0.1") as caught:
        pickle.loads(pickle.dumps(model))
    assert caught[0].message.saved_version == "0.0.1"


# ------------------------------------------------------------ input errors
def test_input_errors_say_what_to_do():
    import pandas as pd

    X, y = _arx_records(1, length=60)
    model = TDLRegressor(hidden_layer_sizes=(), n_init=1, random_state=0)
    with pytest.raises(ValueError, match=r"transposed\? .* pass X\.T"):
        model.fit(X[0].T, y[0])
    with pytest.raises(ValueError, match="list of 2-D arrays"):
        model.fit(np.stack([X[0], X[0]]), y[0])
    frame = pd.DataFrame({"force": X[0][:, 0].astype(object)})
    frame.loc[7, "force"] = "n/a"
    with pytest.raises(ValueError, match=r"'n/a', in column 'force', row 7"):
        model.fit(frame, y[0])
    model.fit(X[0], y[0])
    window = y[0][:20].copy()
    window[5] = np.nan
    with pytest.raises(ValueError, match=r"y_init contains NaN \(first at sample 5\)"):
        model.simulate(X[0], y_init=window)
    with pytest.raises(ValueError, match="y_init is empty"):
        model.simulate(X[0], y_init=y[0][:0])


# -------------------------------------------------------- one list rule
def test_bands_and_scores_read_a_list_alike():
    from sysid_nn._records._data import is_sequence_list
    from sysid_nn.metrics import nrmse
    from sysid_nn.uncertainty import normal_interval

    numbers = [0.0, 1.0, 2.0, 3.0]  # one sequence of four samples
    lower, _ = normal_interval(numbers, [0.1] * 4)
    assert isinstance(lower, np.ndarray) and lower.shape == (4,)
    assert nrmse(numbers, [0.0, 1.0, 2.0, 4.0]) > 0
    nested = [[0.0, 1.0], [2.0, 3.0]]  # one 2-D array, as NumPy reads it
    lower, _ = normal_interval(nested, [[0.1, 0.1], [0.1, 0.1]])
    assert lower.shape == (2, 2)
    scores = nrmse(nested, [[0.0, 1.5], [2.0, 3.5]], multioutput="raw_values")
    assert scores.shape == (2,) and scores[0] == 0.0
    records = [np.zeros(3), np.ones(4)]
    lower, _ = normal_interval(records, [np.ones(3), np.ones(4)])
    assert [a.shape for a in lower] == [(3,), (4,)]
    assert [is_sequence_list(v) for v in (numbers, nested, records)] == [
        False,
        False,
        True,
    ]
