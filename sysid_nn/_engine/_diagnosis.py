"""What ``fit`` reads from the training records before it trains.

Each "auto" setting is one sentence in three parts, each its own function:

* **estimate** (:func:`diagnose_records`): the linear one-step model's
  misfit (its variance, read as an upper estimate of white output noise,
  its share of the spread of the outputs' second difference, its lag-1
  autocorrelation and the share of it a polynomial of the regressors
  explains), the samples per period and the band where the
  outputs clear the misfit, gathered in a :class:`RecordDiagnosis`;
* **decide**: the estimators' ``_choose_shooting``, ``_auto_alpha`` and the
  ISSM's ``_chosen_start`` read the diagnosis;
* **warn** (:func:`warn_white_misfit`): only where the misfit is white and
  not a function of the regressors, never on records whose misfit is smooth.

A **broadband misfit** (the misfit makes up more than 2 % of the spread of
the outputs' second difference) is what the decisions switch on: at fine
sampling it is white measurement noise; on coarse clean records it is
dynamics the three lags do not resolve. Both make the one-step stage fit
to the wrong thing. **Noise** is a broadband misfit that is also white
(lag-1 autocorrelation below 0.2) and below 10 % of the outputs' spread.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass

import numpy as np

from sysid_nn._engine._state_estimation import (
    _FULL_BAND,
    _segments,
    noise_band,
    one_step_misfit,
)
from sysid_nn._exceptions import user_stacklevel
from sysid_nn._records._data import _Data
from sysid_nn._records._record_checks import check_sampling

#: A linear one-step misfit above this share of the spread of the outputs'
#: second difference is broadband: the one-step stage would fit to it.
_BROADBAND_MISFIT = 0.02
#: A misfit above this share of the outputs' spread is a linear model's
#: misfit of a strong nonlinearity, not noise.
_MAX_NOISE_SHARE = 0.1
#: A misfit whose lag-1 autocorrelation is below this is white-like (noise);
#: above it, smooth (dynamics the lags do not resolve); the user guide's
#: training page gives the measurements it separates.
_WHITE_MISFIT_CORRELATION = 0.2
#: A misfit of which squares and cubes of the regressors explain more than
#: this share is a non-linearity's, not noise (see the training page).
_CURVED_MISFIT = 0.1
#: The noise warning suggests decimating records with more samples per
#: period than this.
_DECIMATE_NOISY = 40.0


@dataclass(frozen=True)
class RecordDiagnosis:
    """The estimates the automatic settings of ``fit`` decide by.

    All per output (standardised units) except ``samples_per_period``,
    ``advice`` and ``band_edge``.
    """

    noise_variance: np.ndarray
    misfit_share: np.ndarray
    misfit_correlation: np.ndarray
    misfit_explained: np.ndarray
    samples_per_period: float
    advice: str
    band_edge: float

    @property
    def broadband_misfit(self) -> bool:
        """The one-step misfit is a sizeable part of the second difference."""
        return bool(np.any(self.misfit_share > _BROADBAND_MISFIT))

    @property
    def white_misfit(self) -> np.ndarray:
        """Per output: the misfit is broadband, white, unexplained and small."""
        return (
            (self.misfit_share > _BROADBAND_MISFIT)
            & (self.misfit_correlation < _WHITE_MISFIT_CORRELATION)
            & (self.misfit_explained < _CURVED_MISFIT)
            & (self.noise_variance < _MAX_NOISE_SHARE**2)
        )

    @property
    def free_states_help(self) -> bool:
        """Whether fitted segment states suit these records.

        A broadband misfit below the noise ceiling on every output, with a
        band of the spectrum where the outputs clear it.
        """
        small = bool(np.all(self.noise_variance < _MAX_NOISE_SHARE**2))
        return self.broadband_misfit and small and self.band_edge < _FULL_BAND * 0.5


def diagnose_records(name: str, train: _Data, delay: int) -> RecordDiagnosis:
    """Estimate what the automatic settings need from the training records.

    Also warns, through :func:`~sysid_nn._records._record_checks.check_sampling`,
    when the records are sampled far finer than the defaults handle.
    """
    modelled = _segments(train.starts, train.h)
    spp, advice = check_sampling(name, train.Y, modelled)
    var, correlation, explained = one_step_misfit(
        train.Y, train.U, train.starts, train.h, delay
    )
    d2 = np.concatenate([np.diff(train.Y[a:b], 2, axis=0) for a, b in modelled])
    # The misfit's share of the second difference's spread (at most 1); white
    # noise enters the second difference six-fold in variance.
    share = (
        np.sqrt(np.minimum(6.0 * var / np.maximum(d2.var(axis=0), 1e-300), 1))
        if len(d2) >= 2
        else np.zeros_like(var)
    )
    broadband = bool(np.any(share > _BROADBAND_MISFIT))
    edge = noise_band(train.Y, train.starts, train.h, var) if broadband else 0.5
    return RecordDiagnosis(var, share, correlation, explained, spp, advice, edge)


def warn_white_misfit(est, diagnosis: RecordDiagnosis, advice: str) -> None:
    """Warn that a white misfit swamps the outputs' second difference.

    Only for outputs :attr:`RecordDiagnosis.white_misfit` marks; ``advice``
    is the estimator's remedy.
    """
    white = diagnosis.white_misfit
    if not white.any():
        return
    k = int(np.argmax(np.where(white, diagnosis.misfit_share, -1.0)))
    spp = diagnosis.samples_per_period
    warnings.warn(
        f"A linear one-step model leaves a white misfit on the training outputs "
        f"of {type(est).__name__}: about "
        f"{100 * np.sqrt(diagnosis.noise_variance[k]):.2g} % of their spread "
        f"(output {k}), {100 * diagnosis.misfit_share[k]:.0f} % of the spread of "
        "their second difference, where the dynamics show at this sampling "
        "ratio. It is white measurement noise on the outputs, or excitation "
        "between the samples that the records do not carry (records decimated "
        "without an anti-aliasing filter: decimate with scipy.signal.decimate "
        "instead). Networks trained on such records may lose their advantage "
        f"over the linear model: {advice}use more records, or see the user "
        "guide's pitfalls page on measured records."
        + (
            f" These records have about {spp:.0f} samples per period, where "
            f"the second difference is a small part of the output. "
            f"{diagnosis.advice}"
            if spp > _DECIMATE_NOISY and diagnosis.advice
            else ""
        ),
        UserWarning,
        stacklevel=user_stacklevel(),
    )
