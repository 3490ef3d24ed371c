"""The study's models: what each one sees, how it is set up and fitted."""

from __future__ import annotations

import warnings
from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np
from sklearn.utils import Bunch

from sysid_nn import ISSMRegressor, TDLRegressor
from sysid_nn.study._config import _QUICK_PARAMS, PAPER_ISSM, PAPER_TDL, StudyConfig
from sysid_nn.study._progress import _progress


@dataclass
class StudyModel:
    """An estimator with the record fields it maps and its sampling step.

    Parameters
    ----------
    label : str
        Name shown in figures and tables.
    estimator : estimator
        A TDL or ISSM regressor (fitted after :func:`fit_models`).
    inputs : tuple of str
        Record fields fed as excitation columns.
    outputs : tuple of str
        Record fields modelled; the first one is scored.
    step : int, default=1
        The model sees every ``step``-th sample.

    Examples
    --------
    >>> from sysid_nn.study import StudyModel
    >>> import numpy as np
    >>> from sysid_nn import TDLRegressor
    >>> m = StudyModel("TDL", TDLRegressor(), ("excitation",), ("displacement",), 2)
    >>> records = {"excitation": np.ones((1, 6)), "displacement": np.ones((1, 6))}
    >>> X, y = m.arrays(records)
    >>> X[0].shape, y[0].shape
    ((3, 1), (3,))
    """

    label: str
    estimator: Any
    inputs: tuple[str, ...]
    outputs: tuple[str, ...]
    step: int = 1

    def arrays(
        self, records: Mapping[str, Any], index: Iterable[int] | None = None
    ) -> tuple[list[np.ndarray], list[np.ndarray]]:
        """Estimator inputs and outputs of records, as lists of sequences.

        Parameters
        ----------
        records : mapping of field name to 2-D array or list of 1-D arrays
            One row (or list item) per record.
        index : iterable of int, optional
            Records to take; all by default.

        Returns
        -------
        X : list of ndarray of shape (n_samples, n_inputs)
            Excitation of every record, one column per input field.
        y : list of ndarray of shape (n_samples,) or (n_samples, n_outputs)
            Modelled outputs of every record (1-D for a single output).
        """
        if index is None:
            index = range(len(records[self.inputs[0]]))
        cut = slice(None, None, self.step)
        X, y = [], []
        for j in index:
            X.append(np.column_stack([records[f][j][cut] for f in self.inputs]))
            out = np.column_stack([records[f][j][cut] for f in self.outputs])
            y.append(out[:, 0] if out.shape[1] == 1 else out)
        return X, y


def model_specs(config: StudyConfig) -> dict[str, StudyModel]:
    """Unfitted models of the study, by name.

    ``tdl_paper``: the paper's TDL (6 displacement and 5 excitation lags, 9
    logistic hidden nodes, prediction focus) on every third sample;
    ``issm_paper``: the paper's ISSM (3 states, 7 logistic hidden nodes,
    prediction focus, no linear part) with displacement and velocity
    measured; ``linear``: the linear output-error baseline
    (``hidden_layer_sizes=()``); ``tdl`` and ``issm``: the toolbox's
    defaults (ISSM with displacement and velocity measured).

    Parameters
    ----------
    config : StudyConfig
        ``models`` selects, ``quick``, ``n_jobs`` and ``estimator_params``
        adjust the estimators; the weights are seeded from ``config.seed``.

    Returns
    -------
    dict of str to StudyModel
        The selected models, unfitted, in the order of ``config.models``.

    Examples
    --------
    >>> from sysid_nn.study import StudyConfig, model_specs
    >>> specs = model_specs(StudyConfig(models=("tdl_paper", "linear")))
    >>> {name: (m.label, m.step) for name, m in specs.items()}
    {'tdl_paper': ('TDL (paper)', 3), 'linear': ('linear (OE)', 1)}
    """
    force, disp, both = ("excitation",), ("displacement",), ("displacement", "velocity")
    table: dict[str, tuple[str, Any, dict, tuple[str, ...], int]] = {
        "tdl_paper": (
            "TDL (paper)",
            TDLRegressor,
            PAPER_TDL,
            disp,
            config.paper_tdl_step,
        ),
        "issm_paper": ("ISSM (paper)", ISSMRegressor, PAPER_ISSM, both, 1),
        "linear": ("linear (OE)", TDLRegressor, {"hidden_layer_sizes": ()}, disp, 1),
        "tdl": ("TDL (default)", TDLRegressor, {}, disp, 1),
        "issm": ("ISSM (default)", ISSMRegressor, {}, both, 1),
    }
    weights_seed = config.seeds()["weights"]
    specs = {}
    for name in config.models:
        label, cls, params, outputs, step = table[name]
        params = {
            **params,
            **(_QUICK_PARAMS if config.quick else {}),
            **config.estimator_params.get("all", {}),
            **config.estimator_params.get(name, {}),
            "random_state": weights_seed,
            "n_jobs": config.n_jobs,
        }
        specs[name] = StudyModel(label, cls(**params), force, outputs, step)
    return specs


def fit_models(
    data: Bunch, config: StudyConfig, *, progress: bool = False
) -> dict[str, StudyModel]:
    """Fit every model of :func:`model_specs` on the training records.

    Parameters
    ----------
    data : Bunch
        From :func:`generate_data`.
    config : StudyConfig
        Which models, their settings and seeds (:func:`model_specs`).
    progress : bool, default=False
        Show a progress bar (stderr).

    Returns
    -------
    dict of str to StudyModel
        Fitted models; warnings raised while fitting (e.g. not converged) are
        kept in ``data.fit_warnings[name]`` as text.

    Examples
    --------
    >>> from sysid_nn.study import StudyConfig, fit_models, generate_data
    >>> config = StudyConfig(models=("linear",), n_samples=600, n_test=2, max_lag=10,
    ...                      n_candidates=3, estimator_params={"all": {"n_init": 1}})
    >>> data = generate_data(config)
    >>> models = fit_models(data, config)
    >>> models["linear"].estimator.n_features_in_
    1
    """
    specs = model_specs(config)
    data.fit_warnings = {}
    for name, model in _progress(specs.items(), len(specs), "fitting", progress):
        X, y = model.arrays(data.train)
        X_val, y_val = model.arrays(data.validation)
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            model.estimator.fit(X, y, X_val=X_val, y_val=y_val)
        data.fit_warnings[name] = sorted(
            {f"{w.category.__name__}: {str(w.message).splitlines()[0]}" for w in caught}
        )
    return specs
