"""What a study is: its settings (:class:`StudyConfig`), the models it runs
and the paper's two networks."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from types import MappingProxyType
from typing import Any

import numpy as np

#: The two ways a model is used on unseen data: paper sections 4.3 and 4.4.
MODES = ("prediction", "simulation")

#: Names of the study's models, in the order they are shown.
PAPER_MODELS = ("tdl_paper", "issm_paper", "linear", "tdl", "issm")

#: The paper's TDL network (section 4.2): 6 displacement and 5 excitation
#: lags, 9 logistic hidden nodes, no bypass, plain delays, trained one step
#: ahead; ``TDLRegressor(**PAPER_TDL)``. The paper fits it at dt = 0.03 s.
PAPER_TDL = MappingProxyType(
    {
        "output_lags": 6,
        "input_lags": 5,
        "hidden_layer_sizes": (9,),
        "activation": "logistic",
        "linear_bypass": False,
        "lag_representation": "delays",
        "focus": "prediction",
    }
)

#: The paper's ISSM network (section 4.2): 3 states, 7 logistic hidden
#: nodes, no linear part, trained on the innovations;
#: ``ISSMRegressor(**PAPER_ISSM)`` with displacement and velocity measured.
PAPER_ISSM = MappingProxyType(
    {
        "n_states": 3,
        "hidden_layer_sizes": (7,),
        "activation": "logistic",
        "linear_part": False,
        "focus": "prediction",
    }
)

# Residual tests of figs 4.3-4.4 whose pass rates are reported.
_TESTS = ("whiteness", "cross_positive", "cross_negative")

# Reduced training for the CI-sized run (still every figure and table).
_QUICK_PARAMS = {"n_init": 1}


def _check_int(value: Any, name: str, low: int, hint: str) -> None:
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)):
        raise ValueError(f"{name} must be an integer; got {value!r}. {hint}")
    if value < low:
        raise ValueError(f"{name} must be >= {low}; got {value}. {hint}")


@dataclass(frozen=True)
class StudyConfig:
    """Settings of the section-4 study.

    Parameters
    ----------
    seed : int, default=0
        Master seed in ``[0, 2**32)``; the seeds of the training, validation
        and test records and of the networks' initial weights are drawn from
        it (:class:`numpy.random.SeedSequence`) and stated in the report.
    n_train : int, default=1
        Training records ``K``. They are the ``K`` records whose peak
        displacement is nearest the median of ``n_candidates`` generated
        ones: records of typical amplitude, so that no model has to
        extrapolate far (a small record makes every model extrapolate).
    n_val : int, default=2
        Validation records (early stopping and restart selection).
    n_test : int or None, default=None
        Unseen test realisations ``N_s``; None gives the paper's 25, or 5
        with ``quick``.
    n_candidates : int or None, default=None
        Records generated to choose the training records from; None gives
        ``max(10, 3 * n_train)``.
    n_samples : int, default=2000
        Samples per record (the paper's 20 s at ``dt = 0.01`` s).
    dt : float, default=0.01
        Sampling step of the records, s.
    paper_tdl_step : int, default=3
        The paper's TDL sees every ``paper_tdl_step``-th sample (0.03 s).
    models : tuple of str, default=PAPER_MODELS
        Which of ``"tdl_paper", "issm_paper", "linear", "tdl", "issm"`` to
        run (see :func:`model_specs`).
    quick : bool, default=False
        CI-sized run: 5 test realisations unless ``n_test`` is given, one
        restart per network instead of four.
    n_jobs : int or None, default=None
        Parallel jobs of the Monte Carlo evaluation and of the networks'
        restarts (joblib semantics).
    max_lag : int, default=25
        Largest lag of the residual correlation tests.
    alpha : float, default=0.05
        Significance level of the residual tests (95 % bands as in the paper).
    estimator_params : dict, default={}
        Overrides of the estimators' parameters: ``{"all": {...}}`` for every
        model, ``{name: {...}}`` for one (applied after ``"all"``), e.g.
        ``{"all": {"max_iter": 5, "n_init": 1}}`` for a tiny run.

    Examples
    --------
    >>> from sysid_nn.study import StudyConfig
    >>> config = StudyConfig(seed=1, quick=True)
    >>> config.test_size, config.candidates
    (5, 10)
    >>> StudyConfig(n_test=0)
    Traceback (most recent call last):
    ...
    ValueError: n_test must be >= 1; got 0. Evaluate on at least one test ...
    """

    seed: int = 0
    n_train: int = 1
    n_val: int = 2
    n_test: int | None = None
    n_candidates: int | None = None
    n_samples: int = 2000
    dt: float = 0.01
    paper_tdl_step: int = 3
    models: tuple[str, ...] = PAPER_MODELS
    quick: bool = False
    n_jobs: int | None = None
    max_lag: int = 25
    alpha: float = 0.05
    estimator_params: Mapping[str, Mapping[str, Any]] = field(default_factory=dict)

    def __post_init__(self) -> None:
        _check_int(self.seed, "seed", 0, "Use a seed in [0, 2**32).")
        if self.seed >= 2**32:
            raise ValueError(f"seed must be < 2**32; got {self.seed}.")
        _check_int(self.n_train, "n_train", 1, "Train on at least one record.")
        _check_int(self.n_val, "n_val", 1, "Early stopping needs a validation record.")
        if self.n_test is not None:
            _check_int(
                self.n_test, "n_test", 1, "Evaluate on at least one test record."
            )
        if self.n_candidates is not None:
            _check_int(
                self.n_candidates,
                "n_candidates",
                self.n_train,
                "Generate at least n_train candidate records.",
            )
        step = self.paper_tdl_step
        _check_int(step, "paper_tdl_step", 1, "The paper's TDL uses 3.")
        # The residual tests need more samples than lags on the coarsest grid.
        _check_int(
            self.n_samples,
            "n_samples",
            step * (2 * self.max_lag + 10),
            "Use longer records or a smaller max_lag.",
        )
        if not (np.isfinite(self.dt) and self.dt > 0):
            raise ValueError(f"dt must be a finite number > 0; got {self.dt!r}.")
        if isinstance(self.models, str) or not self.models:
            raise ValueError(
                f"models must be a non-empty tuple of names from {PAPER_MODELS}; "
                f"got {self.models!r}."
            )
        unknown = [m for m in self.models if m not in PAPER_MODELS]
        if unknown or len(set(self.models)) != len(self.models):
            raise ValueError(
                f"models must hold distinct names from {PAPER_MODELS}; got "
                f"{tuple(self.models)!r}."
            )
        object.__setattr__(self, "models", tuple(self.models))
        if self.n_jobs is not None:
            _check_int(self.n_jobs, "n_jobs", -(2**31), "Use None, -1 or >= 1.")
            if self.n_jobs == 0:
                raise ValueError("n_jobs must not be 0; use None, -1 or >= 1.")
        _check_int(self.max_lag, "max_lag", 1, "The paper uses 25.")
        if not 0 < self.alpha < 1:
            raise ValueError(f"alpha must be in (0, 1); got {self.alpha!r}.")
        bad = set(self.estimator_params) - {"all", *PAPER_MODELS}
        if bad:
            raise ValueError(
                f"estimator_params keys must be 'all' or model names from "
                f"{PAPER_MODELS}; got {sorted(bad)}."
            )

    @property
    def test_size(self) -> int:
        """Number of test realisations actually used."""
        if self.n_test is not None:
            return self.n_test
        return 5 if self.quick else 25

    @property
    def candidates(self) -> int:
        """Number of candidate records the training records are chosen from."""
        if self.n_candidates is not None:
            return self.n_candidates
        return max(10, 3 * self.n_train)

    def seeds(self) -> dict[str, int]:
        """Derived seeds of the records and of the networks' weights.

        Returns
        -------
        dict
            ``{"train", "validation", "test", "weights"}`` to ints.

        Examples
        --------
        >>> sorted(StudyConfig(seed=0).seeds())
        ['test', 'train', 'validation', 'weights']
        """
        states = np.random.SeedSequence(self.seed).generate_state(4)
        names = ("train", "validation", "test", "weights")
        return {n: int(s) for n, s in zip(names, states, strict=True)}
