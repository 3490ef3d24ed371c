"""The data layer: sequences, their validation, scaling and stacking.

The ground floor of the estimators: nothing here imports another module of
the package but :mod:`sysid_nn._records._validation`. A fit or a prediction goes
through it in this order:

* :func:`is_sequence_list`, the one rule for "an array or a list of
  sequences" that the estimators, :mod:`sysid_nn.metrics`,
  :mod:`sysid_nn.residuals` and :mod:`sysid_nn.uncertainty` share;
* :class:`_SequenceIO`, the estimators' checks of ``X``, ``y`` and the
  initial conditions (errors name the argument and the sequence), their
  stacking into one standardised :class:`_Data` with history rows, and back;
* :func:`_mean_scale`, the standardisation of the training records.
"""

from __future__ import annotations

from contextlib import contextmanager
from dataclasses import dataclass
from itertools import pairwise

import numpy as np
from sklearn.utils import check_array
from sklearn.utils.validation import _check_feature_names

from sysid_nn._records._validation import check_same_width

#: Segment length of a free run: longer than any record.
_FREE_RUN = np.iinfo(np.int64).max // 4


@dataclass
class _Data:
    """Standardised sequences stacked for the kernels.

    Sequence ``s`` occupies rows ``starts[s]:starts[s + 1]`` of ``Y`` and
    ``U``; its first ``h`` rows are history (initial conditions).
    """

    Y: np.ndarray
    U: np.ndarray
    starts: np.ndarray
    h: int
    #: Leading modelled rows of every sequence left out of it too (a burn-in).
    burn: int = 0
    #: Modelled rows at the start of every sequence its initial state is
    #: fitted to before a validation run (0: none; see ``_fitted_start``).
    start_window: int = 0
    #: Initial states of the sequences (the ISSM's), or None: from the
    #: history rows.
    X0: np.ndarray | None = None
    #: Leading modelled rows of every sequence that are run but never judged:
    #: the training part a held-out tail continues.
    lead: int = 0
    #: Whether the one sequence is the held-out tail of the training records'
    #: last sequence (see :func:`sysid_nn._engine._selection.continuation`).
    tail: bool = False

    @property
    def modelled(self) -> np.ndarray:
        """Row indices of the modelled (non-history) rows."""
        return self._rows_after(0)

    def measured_rows(self, reach: int) -> np.ndarray:
        """Modelled rows whose ``reach`` previous rows are modelled too.

        The rows a least-squares fit on lagged outputs and inputs can use:
        the regressors of the first ``reach`` modelled rows of a sequence
        read its history rows, which hold the rest state, not measurements
        (a record that starts in motion would bias the fit).
        """
        return self._rows_after(reach)

    @property
    def judged(self) -> np.ndarray:
        """Modelled rows that count in a validation loss (after the burn-in
        and the lead)."""
        return self._rows_after(max(self.burn, self.lead))

    def _rows_after(self, skip: int) -> np.ndarray:
        """The modelled rows of every sequence but its first ``skip``."""
        rows = [np.arange(a + self.h + skip, b) for a, b in pairwise(self.starts)]
        return np.concatenate(rows)


def is_sequence_list(data) -> bool:
    """Whether ``data`` is a list of sequences rather than one array.

    A list or tuple is a list of sequences unless every item is a number or
    a list/tuple of numbers: a plain nested list is one array, as NumPy and
    scikit-learn read it; an empty list is neither (callers reject it).

    Examples
    --------
    >>> import numpy as np
    >>> from sysid_nn._records._data import is_sequence_list
    >>> is_sequence_list([np.zeros(3), np.zeros(4)])
    True
    >>> is_sequence_list([[1.0, 2.0], [3.0, 4.0]]), is_sequence_list([1.0, 2.0])
    (False, False)
    """
    if not isinstance(data, (list, tuple)):
        return False
    return not all(
        np.ndim(item) == 0
        or (
            isinstance(item, (list, tuple))
            and all(np.ndim(value) == 0 for value in item)
        )
        for item in data
    )


def _as_sequence_list(X, name: str):
    """Return ``(list_of_arrays, given_as_list)`` (see :func:`is_sequence_list`)."""
    if isinstance(X, (list, tuple)) and len(X) == 0:
        raise ValueError(
            f"{name} is an empty list; pass at least one sequence "
            "(a 2-D array of shape (n_samples, n_features))."
        )
    if is_sequence_list(X):
        return list(X), True
    return [X], False


@contextmanager
def _naming_sequence(where: str, as_list: bool):
    """Prefix an error about one sequence of a list with its place, ``X[i]``."""
    try:
        yield
    except ValueError as exc:
        if as_list:
            raise ValueError(f"{where}: {exc}") from exc
        raise


def _check_text_cells(a, where: str) -> None:
    """A pandas object with a non-numeric cell: name its column and row."""
    import pandas as pd

    frame = a.to_frame() if isinstance(a, pd.Series) else a
    for j, column in enumerate(frame.columns):
        values = frame.iloc[:, j]
        if pd.api.types.is_numeric_dtype(values) or pd.api.types.is_bool_dtype(values):
            continue
        numeric = pd.to_numeric(values, errors="coerce")
        bad = np.flatnonzero(numeric.isna().to_numpy() & values.notna().to_numpy())
        if bad.size:
            i = int(bad[0])
            raise ValueError(
                f"{where} holds a value that is not a number, {values.iloc[i]!r}, "
                f"in column {column!r}, row {frame.index[i]!r} (position {i}). "
                "Convert or remove it before fitting (pandas.to_numeric)."
            )


def _transposed_hint(shape: tuple, where: str) -> str:
    """A hint for a record of one row and many columns: rows are samples."""
    if len(shape) == 2 and shape[0] == 1 and shape[1] > 1:
        return (
            f" {where} has shape {shape}, one sample of {shape[1]} columns: is it "
            f"transposed? Rows are time steps; pass {where}.T."
        )
    return ""


def _float_array(a, name: str, where: str, as_list: bool) -> np.ndarray:
    """``a`` as a float64 array of 1 or 2 dimensions; errors name the sequence."""
    if hasattr(a, "iloc") and hasattr(a, "to_numpy"):
        _check_text_cells(a, where)
    with _naming_sequence(where, as_list):
        arr = check_array(
            a,
            dtype=np.float64,
            ensure_2d=False,
            allow_nd=True,
            ensure_all_finite=False,
            input_name=name,
        )
    if arr.ndim > 2:
        raise ValueError(
            f"{where} must be 2-D (n_samples, n_columns); got a {arr.ndim}-D "
            f"array of shape {arr.shape}. Pass several records as a list of "
            f"2-D arrays, one per record (list({where}) if its first axis "
            "counts the records)."
        )
    return arr


def _check_finite(a: np.ndarray, name: str, index: int | None, as_list: bool) -> None:
    bad = ~np.isfinite(a)
    if bad.any():
        sample = int(np.argwhere(bad)[0][0])
        kind = "NaN" if np.isnan(a[bad]).any() else "inf"
        where = f"{name}[{index}]" if as_list else name
        raise ValueError(
            f"Input {where} contains {kind} (first at sample {sample}); "
            "remove or interpolate non-finite values before fitting or predicting."
        )


def _mean_scale(a: np.ndarray, name: str) -> tuple[np.ndarray, np.ndarray]:
    """Mean and scale of every column, for standardising.

    Computed on the columns divided by a power of two near their peak, which
    is exact and safe from over- and underflow. A varying column whose
    squared deviations overflow float64 when summed, or underflow, cannot be
    standardised (the network and every score would be NaN, or blind to it):
    both raise a ValueError naming ``name``. A constant column (variance
    within the rounding error of the mean, the rule of scikit-learn's
    ``StandardScaler``) is divided by its level where that exceeds 1, so
    that its rounding noise stays negligible, and left unscaled otherwise.
    """
    peak = np.max(np.abs(a), axis=0)
    # At most the peak, so that it is finite; |a / unit| < 2.
    unit = np.ldexp(1.0, np.frexp(peak)[1] - 1)
    rel = a / unit
    rel_mean, rel_var = rel.mean(axis=0), rel.var(axis=0)
    n, eps = len(a), np.finfo(np.float64).eps
    constant = rel_var <= n * eps * rel_var + (n * eps * rel_mean) ** 2
    with np.errstate(over="ignore", under="ignore"):
        mean, scale = unit * rel_mean, unit * np.sqrt(rel_var)
        squares = scale**2
        overflow = ~constant & ~np.isfinite(n * squares)
    underflow = ~constant & (squares < np.finfo(np.float64).tiny)
    for bad, problem in (
        (overflow, "reaches {:.3g}: its variance overflows float64"),
        (underflow, "varies by only {:.3g}: float64 cannot square that"),
    ):
        if bad.any():
            j = int(np.flatnonzero(bad)[0])
            size = peak[j] if bad is overflow else np.ptp(a[:, j])
            raise ValueError(
                f"{name} cannot be standardised: column {j} "
                f"{problem.format(size)}. Rescale {name} (e.g. express it in "
                "other units) before fitting."
            )
    scale[constant] = np.maximum(1.0, peak[constant])
    return mean, scale


class _SequenceIO:
    """Checks, stacking and unstacking of the estimators' sequences (mixin).

    The estimator supplies ``_history_length``, ``_history`` and
    ``_initial_layout`` (its structure's initial conditions) and, once
    fitted, ``_x_mean``, ``_x_scale``, ``_y_mean``, ``_y_scale``.
    """

    def _validate_Xy(self, X, y=None, *, reset: bool, y_required: bool):
        """Validate one sequence or a list of them.

        Returns ``(X_list, y_list or None, given_as_list, y_was_1d)``.
        """
        name = type(self).__name__
        if y_required and y is None:
            raise ValueError(
                f"{name} requires y to be passed, but the target y is None."
            )
        X_list, as_list = _as_sequence_list(X, "X")
        if y is not None:
            y_list, y_as_list = _as_sequence_list(y, "y")
            if y_as_list != as_list:
                raise ValueError(
                    "X and y must both be arrays (one sequence) or both be lists "
                    f"of arrays (several sequences); got X as a "
                    f"{'list' if as_list else 'array'} and y as a "
                    f"{'list' if y_as_list else 'array'}."
                )
            if len(y_list) != len(X_list):
                raise ValueError(
                    f"X and y must hold the same number of sequences; got "
                    f"{len(X_list)} and {len(y_list)}."
                )
        Xs, ys, y_1d = [], [], None
        for i, Xi in enumerate(X_list):
            where = f"X[{i}]" if as_list else "X"
            arr = _float_array(Xi, "X", where, as_list)
            if arr.ndim == 1:
                # scikit-learn's message prints the whole array and suggests
                # reshape(1, -1), which would make a record one time step.
                raise ValueError(
                    f"{where} must be 2-D (n_samples, n_inputs); got a 1-D array of "
                    f"shape {arr.shape}. Reshape your data: a single input is "
                    f"one column, {where}.reshape(-1, 1)."
                )
            # Names as scikit-learn checks them: the first sequence of a fit
            # sets them, every other sequence must match.
            with _naming_sequence(where, as_list):
                _check_feature_names(self, Xi, reset=reset and i == 0)
            Xi = arr
            _check_finite(Xi, "X", i, as_list)
            Xs.append(Xi)
            if y is not None:
                yi = _float_array(y_list[i], "y", f"y[{i}]", as_list)
                if yi.ndim not in (1, 2):
                    raise ValueError(
                        f"y must be 1-D (n_samples,) or 2-D (n_samples, n_outputs); "
                        f"got {yi.ndim} dimensions."
                    )
                this_1d = yi.ndim == 1
                if y_1d is None:
                    y_1d = this_1d
                yi = yi.reshape(len(yi), -1)
                _check_finite(yi, "y", i, as_list)
                if len(yi) != len(Xi):
                    seq = f" in sequence {i}" if as_list else ""
                    raise ValueError(
                        f"X and y must have the same number of samples{seq}; got "
                        f"{len(Xi)} and {len(yi)}." + _transposed_hint(Xi.shape, where)
                    )
                ys.append(yi)
        n_features = check_same_width(Xs, "X", "features")
        if reset:
            self.n_features_in_ = n_features
        elif n_features != self.n_features_in_:
            raise ValueError(
                f"X has {n_features} features, but {name} is expecting "
                f"{self.n_features_in_} features as input."
                + _transposed_hint(Xs[0].shape, "X[0]" if as_list else "X")
            )
        if ys:
            n_outputs = check_same_width(ys, "y", "outputs")
            if not reset and n_outputs != self.n_outputs_:
                raise ValueError(
                    f"y has {n_outputs} outputs, but {name} was fitted with "
                    f"{self.n_outputs_}."
                )
        return Xs, (ys if y is not None else None), as_list, bool(y_1d)

    def _check_lengths(self, Xs, min_length: int, what: str = "X") -> None:
        for i, Xi in enumerate(Xs):
            if len(Xi) < min_length:
                seq = f"sequence {i} of {what}" if len(Xs) > 1 else what
                raise ValueError(
                    f"{seq} has {len(Xi)} sample{'s' if len(Xi) != 1 else ''}; "
                    f"{type(self).__name__} needs at least {min_length} samples "
                    f"per sequence: with these settings it reads {min_length - 1} "
                    "past samples to model one. Use longer records or a smaller "
                    "structure (fewer lags or states, a shorter input_delay)."
                    + _transposed_hint(np.shape(Xi), what)
                )

    # ------------------------------------------------------------ scaling
    def _stack(self, Xs, ys, initial=None, initial_inputs=None) -> _Data:
        """Standardise and stack sequences, with their history rows.

        ``initial_inputs`` (validated by :meth:`_check_initial_inputs`)
        replaces the zero excitation of the last history rows.
        """
        h = self._history_length()
        Yh, Uh = self._history(len(Xs), initial)
        if initial_inputs is not None:
            Uh = [u.copy() for u in Uh]
            for s, past in enumerate(initial_inputs):
                k = min(len(past), h)
                if k:
                    Uh[s][h - k :] = (
                        past[len(past) - k :] - self._x_mean
                    ) / self._x_scale
        n_out = self.n_outputs_
        rows = [h + len(Xi) for Xi in Xs]
        starts = np.concatenate([[0], np.cumsum(rows)]).astype(np.int64)
        Y = np.zeros((starts[-1], n_out))
        U = np.empty((starts[-1], self.n_features_in_))
        for s, Xi in enumerate(Xs):
            a = starts[s]
            Y[a : a + h] = Yh[s]
            U[a : a + h] = Uh[s]
            U[a + h : starts[s + 1]] = (Xi - self._x_mean) / self._x_scale
            if ys is not None:
                Y[a + h : starts[s + 1]] = (ys[s] - self._y_mean) / self._y_scale
        return _Data(Y=Y, U=U, starts=starts, h=h)

    def _unstack(self, Yhat: np.ndarray, data: _Data, as_list: bool, y_1d: bool):
        out = []
        for a, b in zip(data.starts[:-1], data.starts[1:], strict=True):
            yi = Yhat[a + data.h : b] * self._y_scale + self._y_mean
            out.append(yi[:, 0] if y_1d else yi)
        return out if as_list else out[0]

    def _check_initial(self, initial, n_seq: int, as_list: bool, name: str):
        """The initial conditions of every sequence, as arrays of their shape."""
        if initial is None:
            return None
        shape, count, meaning = self._initial_layout()
        out = []
        for i, init in enumerate(self._per_sequence(initial, n_seq, as_list, name)):
            a = np.asarray(init, dtype=np.float64)
            if a.size != np.prod(shape) or not np.all(np.isfinite(a)):
                where = f"{name}[{i}]" if as_list else name
                raise ValueError(
                    f"{where} must hold {count} finite values ({meaning}); got "
                    f"shape {a.shape}."
                )
            out.append(a.reshape(shape))
        return out

    @staticmethod
    def _per_sequence(values, n_seq: int, as_list: bool, name: str) -> list:
        """``values`` as a list with one entry per sequence, or a clear error."""
        items = list(values) if as_list else [values]
        if len(items) != n_seq:
            raise ValueError(
                f"{name} must hold one array per sequence; got {len(items)} for "
                f"{n_seq} sequences."
            )
        return items

    def _check_initial_inputs(self, initial_inputs, n_seq: int, as_list: bool):
        """Validate the excitation before the first sample of each sequence.

        One 2-D array ``(k, n_inputs)`` per sequence (1-D allowed for one
        input), oldest first; only the last rows the lags reach are used,
        and missing older rows are zero excitation.
        """
        if initial_inputs is None:
            return None
        pasts = self._per_sequence(initial_inputs, n_seq, as_list, "initial_inputs")
        out = []
        for i, past in enumerate(pasts):
            a = np.asarray(past, dtype=np.float64)
            if a.ndim == 1 and self.n_features_in_ == 1:
                a = a[:, None]
            where = f"initial_inputs[{i}]" if as_list else "initial_inputs"
            if a.ndim != 2 or a.shape[1] != self.n_features_in_:
                raise ValueError(
                    f"{where} must have shape (n_past_samples, {self.n_features_in_}) "
                    f"(the excitation before the first sample, oldest first); got "
                    f"shape {a.shape}."
                )
            if not np.all(np.isfinite(a)):
                raise ValueError(f"{where} contains NaN or inf; pass finite values.")
            out.append(a)
        return out
