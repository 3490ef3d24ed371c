"""Benchmark loaders and the generated Bouc-Wen benchmark.

The loaders are tested on small files in the official formats written here
into a temporary data directory, laid out as the official loader's cache with
its marker files; the network is switched off, so nothing is downloaded.
The signals are ramps (sample ``i`` holds the value ``i``), so the tests see
exactly which samples of the record each split receives.
"""

from __future__ import annotations

import itertools
import socket
import sys
from pathlib import Path

import numpy as np
import pytest
from scipy.io import savemat

from sysid_nn import datasets


@pytest.fixture(autouse=True)
def no_network(monkeypatch):
    """Any attempt to open a connection fails the test."""

    def refuse(*args, **kwargs):
        raise AssertionError("a test tried to use the network")

    monkeypatch.setattr(socket.socket, "connect", refuse)
    monkeypatch.setattr(socket, "create_connection", refuse)


def _marker(home: Path, name: str) -> Path:
    folder, marker = datasets.MARKERS[name]
    (home / folder).mkdir(parents=True, exist_ok=True)
    (home / folder / marker).touch()
    return home / folder


def _ramp(n: int) -> np.ndarray:
    return np.arange(n, dtype=np.float64)


def _write_silverbox(home: Path, n: int = 131_072) -> None:
    folder = _marker(home, "Silverbox") / "SilverboxFiles"
    folder.mkdir()
    savemat(folder / "SNLS80mV.mat", {"V1": _ramp(n)[None], "V2": -_ramp(n)[None]})


def _write_wh(home: Path, n: int = 188_000) -> None:
    folder = _marker(home, "WienerHammerBenchMark")
    savemat(
        folder / "WienerHammerBenchMark.mat",
        {
            "uBenchMark": _ramp(n)[:, None],
            "yBenchMark": 2 * _ramp(n)[:, None],
            "fs": np.array([[51200.0]]),
        },
    )


def _write_tanks(home: Path, n: int = 1024) -> None:
    folder = _marker(home, "Cascaded_Tanks") / "CascadedTanksFiles"
    folder.mkdir()
    savemat(
        folder / "dataBenchmark.mat",
        {
            "uEst": _ramp(n)[:, None],
            "yEst": _ramp(n)[:, None] + 0.5,
            "uVal": -_ramp(n)[:, None],
            "yVal": -_ramp(n)[:, None] - 0.5,
            "Ts": np.array([[4.0]]),
        },
    )


def _write_emps(home: Path, n: int = 300) -> None:
    folder = _marker(home, "EMPS")
    t = 1e-3 * _ramp(n)[:, None]
    for name, sign in [("DATA_EMPS.mat", 1.0), ("DATA_EMPS_PULSES.mat", -1.0)]:
        savemat(
            folder / name,
            {
                "vir": sign * _ramp(n)[:, None],
                "qm": sign * 10 * _ramp(n)[:, None],
                "qg": np.zeros((n, 1)),
                "t": t,
            },
        )


def _write_boucwen(home: Path) -> None:
    folder = _marker(home, "BoucWen") / "BoucWenFiles" / "Test signals"
    folder = folder / "Validation signals"
    folder.mkdir(parents=True)
    for kind, n in [("multisine", 8192), ("sinesweep", 500)]:
        savemat(folder / f"uval_{kind}.mat", {f"uval_{kind}": _ramp(n)[None]})
        savemat(folder / f"yval_{kind}.mat", {f"yval_{kind}": -_ramp(n)[None]})


def _check_conventions(data) -> None:
    for X, y in zip(
        [*data.get("X_train", []), *data.X_test],
        [*data.get("y_train", []), *data.y_test],
        strict=True,
    ):
        assert X.ndim == 2 and X.shape[1] == 1 and X.dtype == np.float64
        assert y.shape == (X.shape[0],) and y.dtype == np.float64
    assert len(data.test_names) == len(data.X_test)


def test_silverbox_official_split(tmp_path):
    _write_silverbox(tmp_path)
    data = datasets.fetch_silverbox(data_home=tmp_path, download_if_missing=False)
    _check_conventions(data)
    assert data.test_names == ["multisine", "arrow_full", "arrow_no_extrapolation"]
    assert data.dt == pytest.approx(1 / 610.35) and data.n_skip == 50
    # Multisine samples 40650:127400, first 75 % to train, the rest to test.
    split = 40650 + int(0.75 * (127400 - 40650))
    np.testing.assert_array_equal(data.X_train[0][:, 0], np.arange(40650, split))
    np.testing.assert_array_equal(data.y_train[0], -np.arange(40650, split))
    np.testing.assert_array_equal(data.X_test[0][:, 0], np.arange(split, 127400))
    # The arrow, samples 100:40575, and its first 32000 samples.
    np.testing.assert_array_equal(data.X_test[1][:, 0], np.arange(100, 40575))
    np.testing.assert_array_equal(data.X_test[2][:, 0], np.arange(100, 32100))


def test_wiener_hammerstein_official_split(tmp_path):
    _write_wh(tmp_path)
    data = datasets.fetch_wiener_hammerstein(data_home=tmp_path)
    _check_conventions(data)
    assert data.dt == pytest.approx(1 / 51200) and data.n_skip == 50
    np.testing.assert_array_equal(data.X_train[0][:, 0], np.arange(5200, 105200))
    np.testing.assert_array_equal(data.y_train[0], 2 * np.arange(5200, 105200))
    np.testing.assert_array_equal(data.X_test[0][:, 0], np.arange(105200, 184000))


def test_cascaded_tanks_official_split(tmp_path):
    _write_tanks(tmp_path)
    data = datasets.fetch_cascaded_tanks(data_home=tmp_path)
    _check_conventions(data)
    assert data.dt == 4.0 and data.n_skip == 50 and data.test_names == ["test"]
    np.testing.assert_array_equal(data.y_train[0], np.arange(1024) + 0.5)
    np.testing.assert_array_equal(data.y_test[0], -np.arange(1024) - 0.5)


def test_emps_official_split(tmp_path):
    _write_emps(tmp_path)
    data = datasets.fetch_emps(data_home=tmp_path)
    _check_conventions(data)
    assert data.dt == pytest.approx(1e-3) and data.n_skip == 20
    # Input is the motor force vir, output the measured position qm.
    np.testing.assert_array_equal(data.X_train[0][:, 0], np.arange(300))
    np.testing.assert_array_equal(data.y_train[0], 10 * np.arange(300))
    np.testing.assert_array_equal(data.y_test[0], -10 * np.arange(300))


def test_boucwen_test_signals(tmp_path, capsys):
    _write_boucwen(tmp_path)
    data = datasets.fetch_boucwen(data_home=tmp_path)
    _check_conventions(data)
    assert "X_train" not in data
    assert data.test_names == ["multisine", "sinesweep"]
    assert data.dt == pytest.approx(1 / 750) and data.n_skip == 0
    assert [len(y) for y in data.y_test] == [8192, 500]
    np.testing.assert_array_equal(data.y_test[1], -np.arange(500))
    # The official loader's "no official split" warning is not triggered.
    assert "Warning" not in capsys.readouterr().out


WRITERS = {
    "Silverbox": (_write_silverbox, datasets.fetch_silverbox),
    "WienerHammerBenchMark": (_write_wh, datasets.fetch_wiener_hammerstein),
    "Cascaded_Tanks": (_write_tanks, datasets.fetch_cascaded_tanks),
    "EMPS": (_write_emps, datasets.fetch_emps),
    "BoucWen": (_write_boucwen, datasets.fetch_boucwen),
}


@pytest.mark.parametrize("name", [n for n in WRITERS if n != "WienerHammerBenchMark"])
def test_extracted_files_load_without_the_downloaded_archive(tmp_path, name, capsys):
    # (Wiener-Hammerstein's one file is its own marker: nothing to remove.)
    write, fetch = WRITERS[name]
    write(tmp_path)
    folder, marker = datasets.MARKERS[name]
    (tmp_path / folder / marker).unlink()
    data = fetch(data_home=tmp_path)  # downloading would hit the closed network
    _check_conventions(data)
    assert not (tmp_path / folder / marker).exists()
    assert capsys.readouterr().out == ""


def test_missing_files_without_download(tmp_path):
    (tmp_path / "Silverbox").mkdir()
    (tmp_path / "Silverbox" / "SilverboxFiles.zip").touch()  # a marker is not enough
    with pytest.raises(FileNotFoundError) as info:
        datasets.fetch_silverbox(data_home=tmp_path, download_if_missing=False)
    message = str(info.value)
    assert str(tmp_path / "Silverbox" / "SilverboxFiles" / "SNLS80mV.mat") in message
    assert "download_if_missing=True" in message and "\n" not in message


def test_offline_download_failure_is_one_sentence(tmp_path, monkeypatch, capsys):
    def unreachable(*args, **kwargs):
        raise OSError(101, "Network is unreachable")

    monkeypatch.setattr(socket.socket, "connect", unreachable)
    monkeypatch.setattr(socket, "create_connection", unreachable)
    with pytest.raises(ConnectionError) as info:
        datasets.fetch_cascaded_tanks(data_home=tmp_path)
    message = str(info.value)
    assert "\n" not in message
    expected = tmp_path / "Cascaded_Tanks" / "CascadedTanksFiles" / "dataBenchmark.mat"
    assert str(expected) in message and "cannot download" in message
    # No retry chatter on stdout; one line on stderr says what was tried.
    captured = capsys.readouterr()
    assert captured.out == "" and captured.err.count("\n") == 1


def test_mistyped_data_home_is_not_created(tmp_path, monkeypatch):
    typo = tmp_path / "sysid_nn_dta"
    with pytest.raises(FileNotFoundError, match=r"sysid_nn_dta.*spelling"):
        datasets.fetch_emps(data_home=typo)
    assert not typo.exists()
    monkeypatch.setenv("SYSID_NN_DATA", str(typo))
    with pytest.raises(FileNotFoundError, match="SYSID_NN_DATA"):
        datasets.fetch_emps()
    assert not typo.exists()


def test_missing_official_loader_names_the_extra(tmp_path, monkeypatch):
    monkeypatch.setitem(sys.modules, "nonlinear_benchmarks", None)
    with pytest.raises(ImportError) as info:
        datasets.fetch_emps(data_home=tmp_path)
    # Right from the package index and from a checkout alike.
    assert "pip install nonlinear-benchmarks==1.0.1" in str(info.value)
    assert 'pip install ".[benchmarks]"' in str(info.value)


def test_get_data_home(tmp_path, monkeypatch):
    target = tmp_path / "from_env"
    target.mkdir()
    monkeypatch.setenv("SYSID_NN_DATA", str(target))
    assert datasets.get_data_home() == str(target.resolve())
    explicit = tmp_path / "explicit" / "nested"
    explicit.mkdir(parents=True)
    assert datasets.get_data_home(explicit) == str(explicit.resolve())
    monkeypatch.delenv("SYSID_NN_DATA")
    monkeypatch.setenv("HOME", str(tmp_path / "home"))
    assert datasets.get_data_home() == str(tmp_path / "home" / "sysid_nn_data")


def test_environment_variable_selects_the_cache(tmp_path, monkeypatch):
    _write_emps(tmp_path)
    monkeypatch.setenv("SYSID_NN_DATA", str(tmp_path))
    data = datasets.fetch_emps(download_if_missing=False)
    assert len(data.y_train[0]) == 300


# ---------------------------------------------------------------------------
# Generated Bouc-Wen benchmark
# ---------------------------------------------------------------------------
@pytest.fixture(scope="module")
def boucwen():
    return datasets.make_boucwen_benchmark(n_periods=3, random_state=0)


@pytest.fixture(scope="module")
def quiet():
    return datasets.make_boucwen_benchmark(n_periods=3, noise_rms=0.0, random_state=0)


def test_boucwen_linear_mode_matches_the_specification(boucwen):
    # Free decay of a small velocity kick: the hysteretic force stays in its
    # linear range, so the motion is the linear mode of the specification.
    osc = boucwen.oscillator
    dt = 1 / 15000
    res = osc.simulate(np.zeros(15000), dt, initial_state=[0.0, 1e-5, 0.0])
    x = res.displacement
    up = np.flatnonzero((x[:-1] < 0) & (x[1:] >= 0))
    # Sub-sample interpolation of the upward zero crossings.
    t_up = (up + x[up] / (x[up] - x[up + 1])) * dt
    f_damped = 1 / np.mean(np.diff(t_up))
    peaks = [np.max(x[a:b]) for a, b in itertools.pairwise(up)]
    delta = np.mean(np.diff(np.log(peaks)))
    zeta = -delta / np.sqrt(4 * np.pi**2 + delta**2)
    f_natural = f_damped / np.sqrt(1 - zeta**2)
    assert f_natural == pytest.approx(35.6, abs=0.05)
    assert 100 * zeta == pytest.approx(1.12, abs=0.01)


def test_boucwen_training_data(boucwen):
    u, y = boucwen.X_train[0], boucwen.y_train[0]
    assert u.shape == (3 * 8192, 1) and y.shape == (3 * 8192,)
    assert boucwen.dt == pytest.approx(1 / 750) and boucwen.n_skip == 0
    period = u[:8192, 0]
    assert np.sqrt(np.mean(period**2)) == pytest.approx(50.0, rel=1e-6)
    np.testing.assert_allclose(u[8192:16384, 0], period)
    # Lines floor(5 / f_res) .. ceil(150 / f_res) of the 8192-point period.
    spectrum = np.abs(np.fft.rfft(period))
    excited = np.flatnonzero(spectrum > 1e-6 * spectrum.max())
    np.testing.assert_array_equal(excited, np.arange(54, 1640))
    # From rest: the first period holds a transient, later ones are periodic.
    clean = boucwen.y_train_noise_free[0]
    p2, p3 = clean[8192:16384], clean[16384:]
    assert np.sqrt(np.mean((p3 - p2) ** 2)) < 1e-3 * np.std(p3)
    assert np.sqrt(np.mean((clean[:8192] - p3) ** 2)) > 1e-2 * np.std(p3)


def test_boucwen_noise_level(boucwen):
    noise = boucwen.y_train[0] - boucwen.y_train_noise_free[0]
    assert np.sqrt(np.mean(noise**2)) == pytest.approx(8e-6, rel=0.03)
    assert abs(noise.mean()) < 4 * 8e-6 / np.sqrt(noise.size)
    # Band-limited to 0-375 Hz at fs = 750 Hz: white, flat over the band.
    lag1 = np.corrcoef(noise[:-1], noise[1:])[0, 1]
    assert abs(lag1) < 4 / np.sqrt(noise.size)
    power = np.abs(np.fft.rfft(noise)) ** 2
    low, high = power[1 : power.size // 2].mean(), power[power.size // 2 :].mean()
    assert low / high == pytest.approx(1.0, abs=0.1)


def test_boucwen_test_data_are_noise_free(boucwen, quiet):
    u_ms, u_sw = (X[:, 0] for X in boucwen.X_test)
    y_sw = boucwen.y_test[1]
    assert u_ms.shape == (8192,) and u_sw.shape == (153_000,)
    assert np.sqrt(np.mean(u_ms**2)) == pytest.approx(50.0, rel=1e-6)
    # A fresh multisine: not the training one.
    assert not np.allclose(u_ms, boucwen.X_train[0][:8192, 0])
    # The sweep has amplitude 40 N and starts from rest (up to the decimation
    # filter, which is not causal).
    assert np.max(np.abs(u_sw)) == pytest.approx(40.0, rel=1e-3)
    assert abs(y_sw[0]) < 1e-4 * np.std(y_sw)
    # Noise-free: the same as when the training data have no noise at all.
    for y, y_quiet in zip(boucwen.y_test, quiet.y_test, strict=True):
        np.testing.assert_array_equal(y, y_quiet)


def test_boucwen_reproducible(boucwen, quiet):
    # The same seed gives the same signals, whatever the noise level.
    for key in ["X_train", "y_train_noise_free", "X_test"]:
        for a, b in zip(boucwen[key], quiet[key], strict=True):
            np.testing.assert_array_equal(a, b)
    other = datasets.make_boucwen_benchmark(n_periods=1, random_state=1)
    assert not np.allclose(other.X_train[0], boucwen.X_train[0][:8192])


def test_boucwen_noise_free_option_and_errors(quiet):
    np.testing.assert_array_equal(quiet.y_train[0], quiet.y_train_noise_free[0])
    with pytest.raises(ValueError, match="noise_rms"):
        datasets.make_boucwen_benchmark(noise_rms=-1.0)
    with pytest.raises(ValueError, match="n_periods"):
        datasets.make_boucwen_benchmark(n_periods=0)
