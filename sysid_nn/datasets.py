"""Benchmark data sets of the system identification community.

Loaders for the measured benchmarks of nonlinearbenchmark.org (Silverbox,
Wiener-Hammerstein 2009, Cascaded Tanks, EMPS and the Bouc-Wen benchmark's
test signals) and a generator of the Bouc-Wen benchmark's training data as its
specification prescribes (:func:`make_boucwen_benchmark`).

Every function returns the package's data conventions: lists of experiments,
each ``X`` of shape ``(n_samples, 1)`` and ``y`` of shape ``(n_samples,)``,
the sampling time ``dt`` and ``n_skip``, the number of initial samples of each
test sequence that scoring leaves out (the benchmark's state-initialisation
window: the community scores a free run on the samples after it, whose
initial state may be estimated from the window's measured outputs, as
``simulate(X, y_init=y[:n_skip])`` does).
The train/test splits are the ones of the community's loader,
``nonlinear-benchmarks`` 1.0.1, which the ``fetch_*`` functions call to
download and read the files: install it with ``pip install
nonlinear-benchmarks==1.0.1`` (the ``benchmarks`` extra: ``pip install
".[benchmarks]"`` in a checkout of this package).

Downloaded files are kept in a data directory (see :func:`get_data_home`,
scikit-learn's convention): once a benchmark is there, loading it needs no
network. A benchmark is there when its extracted files are, laid out as the
official loader extracts them (e.g.
``Silverbox/SilverboxFiles/SNLS80mV.mat``; each loader's docstring names its
files); the archive the loader downloads
(its *marker* file, e.g. ``Silverbox/SilverboxFiles.zip``) is not needed.
"""

from __future__ import annotations

import contextlib
import io
import math
import os
import sys
from pathlib import Path
from unittest import mock

import numpy as np
import scipy.signal
from sklearn.utils import Bunch, check_random_state

from sysid_nn import excitation as _exc
from sysid_nn._records._validation import check_positive, check_positive_int
from sysid_nn.oscillator import HystereticOscillator

__all__ = [
    "fetch_boucwen",
    "fetch_cascaded_tanks",
    "fetch_emps",
    "fetch_silverbox",
    "fetch_wiener_hammerstein",
    "get_data_home",
    "make_boucwen_benchmark",
]

#: Environment variable that overrides the default data directory.
DATA_HOME_ENV = "SYSID_NN_DATA"

#: Folder and marker file of each benchmark in the official loader's cache.
MARKERS = {
    "Silverbox": ("Silverbox", "SilverboxFiles.zip"),
    "WienerHammerBenchMark": ("WienerHammerBenchMark", "WienerHammerBenchMark.mat"),
    "Cascaded_Tanks": ("Cascaded_Tanks", "CascadedTanksFiles.zip"),
    "EMPS": ("EMPS", "EMPS.zip"),
    "BoucWen": (
        "BoucWen",
        "Hysteretic Benchmark with a Dynamic Nonlinearity_1_all.zip",
    ),
}

_BOUCWEN_TESTS = "BoucWenFiles/Test signals/Validation signals"

#: Extracted files the official loader reads, relative to each benchmark's
#: folder in the data directory.
FILES = {
    "Silverbox": ("SilverboxFiles/SNLS80mV.mat",),
    "WienerHammerBenchMark": ("WienerHammerBenchMark.mat",),
    "Cascaded_Tanks": ("CascadedTanksFiles/dataBenchmark.mat",),
    "EMPS": ("DATA_EMPS.mat", "DATA_EMPS_PULSES.mat"),
    "BoucWen": tuple(
        f"{_BOUCWEN_TESTS}/{kind}val_{signal}.mat"
        for signal in ("multisine", "sinesweep")
        for kind in "uy"
    ),
}

#: How to install the official loader: from the package index, or the extra.
_INSTALL_HINT = (
    "install it with: pip install nonlinear-benchmarks==1.0.1 (or, in a checkout "
    'of sysid_nn, pip install ".[benchmarks]")'
)


def get_data_home(data_home: str | os.PathLike | None = None) -> str:
    """Return the path of the data directory.

    The directory holds the downloaded benchmark files. By default it is
    ``~/sysid_nn_data``, created when missing; the environment variable
    ``SYSID_NN_DATA`` or the ``data_home`` argument choose another one (as
    scikit-learn's ``get_data_home`` does with ``SCIKIT_LEARN_DATA``), which
    must exist: a mistyped folder is an error, not a new empty one. ``~`` is
    expanded.

    Parameters
    ----------
    data_home : str or path-like, default=None
        The data directory; ``None`` uses ``SYSID_NN_DATA`` if it is set,
        else ``~/sysid_nn_data``.

    Returns
    -------
    str
        The absolute path of the data directory.

    Raises
    ------
    FileNotFoundError
        A ``data_home`` or ``SYSID_NN_DATA`` that is not an existing folder.

    Examples
    --------
    >>> import tempfile
    >>> from sysid_nn.datasets import get_data_home
    >>> folder = tempfile.mkdtemp()
    >>> get_data_home(folder) == folder
    True
    """
    source = "data_home"
    if data_home is None and DATA_HOME_ENV in os.environ:
        data_home, source = os.environ[DATA_HOME_ENV], DATA_HOME_ENV
    if data_home is None:
        path = Path("~", "sysid_nn_data").expanduser().resolve()
        path.mkdir(parents=True, exist_ok=True)
        return str(path)
    path = Path(data_home).expanduser().resolve()
    if not path.is_dir():
        raise FileNotFoundError(
            f"{source} {str(data_home)!r} is not an existing folder; check its "
            "spelling, or create it first to keep the benchmark files there."
        )
    return str(path)


def _official_loader():
    try:
        import nonlinear_benchmarks
    except ImportError as exc:
        raise ImportError(
            "The benchmark loaders need the optional dependency "
            "'nonlinear-benchmarks' (the community's loader, which downloads and "
            f"splits the files); {_INSTALL_HINT}."
        ) from exc
    return nonlinear_benchmarks


def _call_official(name: str, data_home, download_if_missing: bool, **kwargs) -> object:
    """Call the official loader ``name`` with the data directory as its cache."""
    module = _official_loader()
    if name == "BoucWen":  # it has no official split, so it lives apart
        module = module.not_splitted_benchmarks
    loader = getattr(module, name)
    home = get_data_home(data_home)
    folder = Path(home) / MARKERS[name][0]
    missing = [f for f in FILES[name] if not (folder / f).is_file()]
    if not missing:
        # The files are here: the official loader reads them, and its download
        # step (which wants the archive as well) is skipped.
        def here(url, name_dir, *args, dir_placement=None, **kw) -> str:
            return os.path.join(dir_placement, name_dir)

        with mock.patch.object(sys.modules[loader.__module__], "cashed_download", here):
            return loader(dir_placement=home, **kwargs)
    where = f"{folder / missing[0]}" + (
        f" (and {len(missing) - 1} more file(s))" if len(missing) > 1 else ""
    )
    if not download_if_missing:
        raise FileNotFoundError(
            f"{name} benchmark not found: no {where}; put the benchmark's "
            f"extracted files in {folder}, or pass download_if_missing=True to "
            "download them."
        )
    # The official loader reports retries and progress on stdout; a failure
    # here is one sentence instead.
    print(f"downloading the {name} benchmark into {folder} ...", file=sys.stderr)
    with contextlib.redirect_stdout(io.StringIO()):
        try:
            return loader(dir_placement=home, **kwargs)
        except Exception as exc:  # the loader raises bare Exception/ValueError
            reason = str(exc).strip().splitlines()[-1] if str(exc).strip() else ""
            raise ConnectionError(
                f"cannot download the {name} benchmark into {folder} ({reason}); "
                f"with no network, put its extracted files there (missing: {where})."
            ) from None


def _sequence(data) -> tuple[np.ndarray, np.ndarray]:
    """``(X, y)`` of one official record: ``X`` 2-D, ``y`` 1-D, float64 copies."""
    u = np.array(data.u, dtype=np.float64).reshape(-1, 1)
    y = np.array(data.y, dtype=np.float64).reshape(-1)
    return u, y


def _fetch(name, test_names, descr, data_home, download_if_missing) -> Bunch:
    """Load a benchmark split by the official loader into the conventions."""
    train, tests = _call_official(name, data_home, download_if_missing)
    tests = list(tests) if isinstance(tests, (list, tuple)) else [tests]
    X_train, y_train = _sequence(train)
    X_test, y_test = map(list, zip(*(_sequence(d) for d in tests), strict=True))
    return Bunch(
        X_train=[X_train],
        y_train=[y_train],
        X_test=X_test,
        y_test=y_test,
        test_names=list(test_names),
        dt=float(train.sampling_time),
        n_skip=int(tests[0].state_initialization_window_length),
        DESCR=descr,
    )


#: Parameters section shared by the loaders' docstrings.
_LOADER_PARAMETERS_DOC = """\
    Parameters
    ----------
    data_home : str or path-like, default=None
        Data directory (see :func:`get_data_home`).
    download_if_missing : bool, default=True
        Download the files when they are not in ``data_home``; with
        ``False`` a missing benchmark raises :class:`FileNotFoundError`
        naming the first missing file; a failed download raises
        :class:`ConnectionError`. Extracted files already in ``data_home``
        are read without any download."""

#: Returns section shared by the loaders of split benchmarks.
_LOADER_RETURNS_DOC = """\
    Returns
    -------
    Bunch
        ``X_train``, ``y_train``: lists with one experiment (``X`` of shape
        ``(n_samples, 1)``, ``y`` of shape ``(n_samples,)``), training and
        validation data together (hold out its tail for validation);
        ``X_test``, ``y_test``: lists of the test experiments, named in
        ``test_names``; ``dt``: sampling time in seconds; ``n_skip``: initial
        samples of each test sequence that scoring skips; ``DESCR``: the
        benchmark, its split and its reference."""


def _doc(func):
    func.__doc__ = func.__doc__.replace(
        "    {parameters}", _LOADER_PARAMETERS_DOC
    ).replace("    {returns}", _LOADER_RETURNS_DOC)
    return func


@_doc
def fetch_silverbox(
    *, data_home: str | os.PathLike | None = None, download_if_missing: bool = True
) -> Bunch:
    """Load the Silverbox benchmark (an electronic Duffing oscillator).

    Input ``V1`` (V), output ``V2`` (V), sampled at 610.35 Hz (Wigren &
    Schoukens, 2013). Official split: the first 75 % of the multisine record
    (samples 40650 to 127400) for training and validation, its last 25 % for
    testing (``"multisine"``); the arrow (samples 100 to 40575) is a second
    test, in full (``"arrow_full"``, whose end requires extrapolation beyond
    the training amplitudes) and its first 32 000 samples
    (``"arrow_no_extrapolation"``). Scoring skips 50 samples. File read
    from the data directory: ``Silverbox/SilverboxFiles/SNLS80mV.mat``.

    {parameters}

    {returns}

    Examples
    --------
    >>> from sysid_nn.datasets import fetch_silverbox
    >>> data = fetch_silverbox()  # doctest: +SKIP
    >>> data.test_names, data.n_skip  # doctest: +SKIP
    (['multisine', 'arrow_full', 'arrow_no_extrapolation'], 50)
    """
    return _fetch(
        "Silverbox",
        ["multisine", "arrow_full", "arrow_no_extrapolation"],
        "Silverbox (Wigren & Schoukens 2013): electronic Duffing oscillator; "
        "train on the first 75 % of the multisine, test on its rest and on the "
        "arrow (full, and its first 32000 samples without extrapolation).",
        data_home,
        download_if_missing,
    )


@_doc
def fetch_wiener_hammerstein(
    *, data_home: str | os.PathLike | None = None, download_if_missing: bool = True
) -> Bunch:
    """Load the Wiener-Hammerstein 2009 benchmark (an electronic circuit).

    A static diode non-linearity between two sixth-order linear filters,
    excited by filtered Gaussian noise, sampled at 51.2 kHz (Schoukens,
    Suykens & Ljung, 2009). Official split: samples 5200 to 184000, the
    first 100 000 for training and validation, the remaining 78 800 for
    testing (``"test"``). Scoring skips 50 samples. File read from the data
    directory: ``WienerHammerBenchMark/WienerHammerBenchMark.mat``.

    {parameters}

    {returns}

    Examples
    --------
    >>> from sysid_nn.datasets import fetch_wiener_hammerstein
    >>> data = fetch_wiener_hammerstein()  # doctest: +SKIP
    >>> len(data.y_train[0]), len(data.y_test[0])  # doctest: +SKIP
    (100000, 78800)
    """
    return _fetch(
        "WienerHammerBenchMark",
        ["test"],
        "Wiener-Hammerstein 2009 (Schoukens, Suykens & Ljung 2009): samples "
        "5200:184000, the first 100000 to train, the rest to test.",
        data_home,
        download_if_missing,
    )


@_doc
def fetch_cascaded_tanks(
    *, data_home: str | os.PathLike | None = None, download_if_missing: bool = True
) -> Bunch:
    """Load the Cascaded Tanks benchmark (two water tanks with overflow).

    Input: pump voltage; output: water level of the lower tank (both in V),
    sampled every 4 s (Schoukens, Mattson, Wigren & Noël, 2016). Official
    split: the estimation record for training and validation, the
    validation record for testing (``"test"``), 1024 samples each. Scoring
    skips 50 samples. File read from the data directory:
    ``Cascaded_Tanks/CascadedTanksFiles/dataBenchmark.mat``.

    {parameters}

    {returns}

    Examples
    --------
    >>> from sysid_nn.datasets import fetch_cascaded_tanks
    >>> data = fetch_cascaded_tanks()  # doctest: +SKIP
    >>> data.dt, data.n_skip  # doctest: +SKIP
    (4.0, 50)
    """
    return _fetch(
        "Cascaded_Tanks",
        ["test"],
        "Cascaded Tanks (Schoukens, Mattson, Wigren & Noel 2016): train on the "
        "estimation record, test on the validation record.",
        data_home,
        download_if_missing,
    )


@_doc
def fetch_emps(
    *, data_home: str | os.PathLike | None = None, download_if_missing: bool = True
) -> Bunch:
    """Load the EMPS benchmark (an electro-mechanical positioning system).

    Input: motor force ``vir`` (N); output: measured position ``qm`` (m),
    sampled at 1 kHz, recorded in closed loop (Janot, Gautier & Brunot,
    2019). Official split: ``DATA_EMPS`` for training and validation,
    ``DATA_EMPS_PULSES`` for testing (``"test"``). Scoring skips 20 samples.
    Files read from the data directory: ``EMPS/DATA_EMPS.mat`` and
    ``EMPS/DATA_EMPS_PULSES.mat``.

    {parameters}

    {returns}

    Examples
    --------
    >>> from sysid_nn.datasets import fetch_emps
    >>> data = fetch_emps()  # doctest: +SKIP
    >>> data.n_skip  # doctest: +SKIP
    20
    """
    return _fetch(
        "EMPS",
        ["test"],
        "EMPS (Janot, Gautier & Brunot 2019): train on DATA_EMPS, test on "
        "DATA_EMPS_PULSES.",
        data_home,
        download_if_missing,
    )


#: Sampling frequency of the Bouc-Wen benchmark, Hz.
BOUCWEN_FS = 750.0


@_doc
def fetch_boucwen(
    *, data_home: str | os.PathLike | None = None, download_if_missing: bool = True
) -> Bunch:
    """Load the official test signals of the Bouc-Wen benchmark.

    The benchmark (Noël & Schoukens, 2016) has no measured training data:
    each user generates them from its specification (see
    :func:`make_boucwen_benchmark`). The official files hold two noise-free
    test records at 750 Hz: ``"multisine"``, one period of the steady-state
    response to a random-phase multisine, and ``"sinesweep"``, the response
    to a sine sweep. The official loader defines no initialisation window
    (``n_skip = 0``); the multisine record is periodic, so a model can be run
    from rest over a few repetitions of its input and scored on the last.
    Files read from the data directory: ``uval_multisine.mat``,
    ``yval_multisine.mat``, ``uval_sinesweep.mat`` and ``yval_sinesweep.mat``
    in ``BoucWen/BoucWenFiles/Test signals/Validation signals``.

    {parameters}

    Returns
    -------
    Bunch
        ``X_test``, ``y_test``: lists of the two test experiments (``X`` of
        shape ``(n_samples, 1)`` in N, ``y`` of shape ``(n_samples,)`` in m),
        named in ``test_names``; ``dt``: ``1 / 750`` s; ``n_skip``: 0;
        ``DESCR``: the benchmark and its reference.

    Examples
    --------
    >>> from sysid_nn.datasets import fetch_boucwen
    >>> data = fetch_boucwen()  # doctest: +SKIP
    >>> data.test_names  # doctest: +SKIP
    ['multisine', 'sinesweep']
    """
    records = _call_official(
        "BoucWen", data_home, download_if_missing, train_test_split=False
    )
    pairs = [_sequence(d) for d in records]
    return Bunch(
        X_test=[p[0] for p in pairs],
        y_test=[p[1] for p in pairs],
        test_names=["multisine", "sinesweep"],
        dt=1.0 / BOUCWEN_FS,
        n_skip=0,
        DESCR="Bouc-Wen benchmark (Noel & Schoukens 2016): official test "
        "signals; generate the training data with make_boucwen_benchmark.",
    )


# ---------------------------------------------------------------------------
# The Bouc-Wen benchmark generated from its specification
# ---------------------------------------------------------------------------
#: Integration runs at 20 times the sampling frequency (15 kHz).
_UPSAMPLING = 20


def _decimate(y: np.ndarray) -> np.ndarray:
    """Low-pass filter and downsample by 20 as the specification's script does.

    The script decimates by the prime factors of 20 in turn, each with
    MATLAB's ``decimate(y, r, 'fir')``: a 30th-order Hamming-window FIR low
    pass with its delay compensated.
    """
    for factor in (2, 2, 5):
        y = scipy.signal.decimate(y, factor, n=30, ftype="fir", zero_phase=True)
    return y


def _simulate_decimated(osc: HystereticOscillator, force: np.ndarray, mass: float):
    """Displacement at 750 Hz of the response to ``force`` given at 15 kHz."""
    dt = 1.0 / (BOUCWEN_FS * _UPSAMPLING)
    y = osc.simulate(force / mass, dt).displacement
    return _decimate(y)


def _fine_multisine(n_periods: int, rms: float, rng) -> np.ndarray:
    """``n_periods`` periods of the specification's multisine at 15 kHz.

    The script excites the FFT lines ``floor(5 / f_res)`` to
    ``ceil(150 / f_res)`` of an 8192 * 20-point period (``f_res`` = 750 / 8192
    Hz) with unit amplitude and uniform random phase, scaled to ``rms``.
    """
    n_fine = 8192 * _UPSAMPLING
    f_res = BOUCWEN_FS / 8192
    lo, hi = math.floor(5.0 / f_res), math.ceil(150.0 / f_res)
    period = _exc.multisine(
        n_fine,
        1.0 / (BOUCWEN_FS * _UPSAMPLING),
        (lo - 0.5) * f_res,
        (hi + 0.5) * f_res,
        rms=rms,
        random_state=rng,
    )
    return np.tile(period, n_periods)


def make_boucwen_benchmark(
    n_periods: int = 5,
    *,
    noise_rms: float = 8e-6,
    random_state: int | np.random.RandomState | None = None,
) -> Bunch:
    """Generate the Bouc-Wen benchmark's data as its specification prescribes.

    The system is the hysteretic benchmark of Noël & Schoukens (2016), a
    mass of 2 kg on a spring and damper (``c = 10`` N s/m, ``k = 5e4`` N/m)
    with a Bouc-Wen hysteretic force (``alpha = 5e4`` N/m, ``beta = 1e3``,
    ``gamma = 0.8``, ``delta = -1.1``, ``nu = 1``), built with
    :meth:`sysid_nn.HystereticOscillator.from_physical`; its linear mode is
    at 35.6 Hz with 1.12 % damping. As the specification's script does, the
    excitation is designed and the response integrated at 15 kHz (20 times
    the sampling frequency; one RK4 step per sample, the force held over it), the
    displacement is decimated to 750 Hz (FIR low pass by the factors 2, 2
    and 5) and the force downsampled, and one extra period is simulated and
    dropped so that the filter's end
    effects do not reach the data.

    * Training: ``n_periods`` periods of a random-phase multisine (5 to 150
      Hz, RMS 50 N, 8192 samples per period at 750 Hz), from rest, with
      zero-mean Gaussian output noise of RMS ``noise_rms`` (band-limited to
      0-375 Hz, i.e. white at 750 Hz) added to the displacement.
    * Test, noise-free: ``"multisine"``, one steady-state period of the
      response to a fresh multisine (the third of four simulated periods);
      ``"sinesweep"``, the response from rest to a linear sine sweep of
      amplitude 40 N from 20 Hz at 10 Hz per minute, 153 000 samples.

    Parameters
    ----------
    n_periods : int, default=5
        Training periods (the specification's 5), each 8192 samples.
    noise_rms : float, default=8e-6
        RMS of the output noise on the training data, in m (``>= 0``).
    random_state : int, RandomState instance or None, default=None
        Seed of the multisine phases and of the noise.

    Returns
    -------
    Bunch
        ``X_train``, ``y_train``: lists with the training experiment (force
        ``(n_periods * 8192, 1)`` in N, noisy displacement in m);
        ``y_train_noise_free``: the same displacement without noise;
        ``X_test``, ``y_test``: lists of the test experiments named in
        ``test_names``; ``dt``: ``1 / 750`` s; ``n_skip``: 0 (the multisine
        test is one steady-state period: run a model from rest over the
        repeated input and score the last period); ``oscillator``: the
        simulated :class:`~sysid_nn.HystereticOscillator` (force per unit
        mass as its input); ``DESCR``: the benchmark.

    Examples
    --------
    >>> from sysid_nn.datasets import make_boucwen_benchmark
    >>> data = make_boucwen_benchmark(n_periods=1, random_state=0)
    >>> data.X_train[0].shape, data.test_names
    ((8192, 1), ['multisine', 'sinesweep'])
    >>> round(float(data.y_train[0].std() * 1e3), 2)  # displacement in mm
    0.6...
    """
    n_periods = check_positive_int(n_periods, "n_periods")
    noise_rms = check_positive(noise_rms, "noise_rms", allow_zero=True)
    rng = check_random_state(random_state)
    mass = 2.0
    # One RK4 step per 15 kHz sample, the specification's integration step:
    # 6e-6 of the response's RMS from a four-substep run, far below the noise.
    osc = HystereticOscillator.from_physical(mass=mass, n_substeps=1)
    n_period = 8192

    # Training: n_periods + 1 periods; the last absorbs the filter's end effect.
    force = _fine_multisine(n_periods + 1, 50.0, rng)
    y_clean = _simulate_decimated(osc, force, mass)[: n_periods * n_period]
    u_train = force[::_UPSAMPLING][: n_periods * n_period]
    noise = noise_rms * rng.standard_normal(y_clean.shape)

    # Test multisine: steady state reached within two periods (the linear
    # mode's time constant is 0.4 s, a period 10.9 s); a fourth period
    # absorbs the filter's end effect.
    force = _fine_multisine(4, 50.0, rng)
    y_ms = _simulate_decimated(osc, force, mass)[2 * n_period : 3 * n_period]
    u_ms = force[::_UPSAMPLING][2 * n_period : 3 * n_period]

    # Sine sweep from rest, extended past its end so the filter's edge is cut.
    n_sweep, n_pad = 153_000, 256
    t = np.arange((n_sweep + n_pad) * _UPSAMPLING) / (BOUCWEN_FS * _UPSAMPLING)
    rate = 10.0 / 60.0  # Hz per second
    force = 40.0 * np.sin(2.0 * np.pi * (20.0 * t + 0.5 * rate * t**2))
    y_sw = _simulate_decimated(osc, force, mass)[:n_sweep]
    u_sw = force[::_UPSAMPLING][:n_sweep]

    return Bunch(
        X_train=[u_train[:, None]],
        y_train=[y_clean + noise],
        y_train_noise_free=[y_clean],
        X_test=[u_ms[:, None], u_sw[:, None]],
        y_test=[y_ms, y_sw],
        test_names=["multisine", "sinesweep"],
        dt=1.0 / BOUCWEN_FS,
        n_skip=0,
        oscillator=osc,
        DESCR="Bouc-Wen benchmark (Noel & Schoukens 2016) generated from its "
        "specification: multisine training data with output noise, noise-free "
        "multisine and sine-sweep test data.",
    )
