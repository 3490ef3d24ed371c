"""Tests of the ``sysid-nn reproduce``, ``fit`` and ``validate`` commands."""

import numpy as np
import pandas as pd
import pytest

from sysid_nn._saved import _read_bundle
from sysid_nn.cli import main
from sysid_nn.study import FIGURES


def _one_error_line(capsys):
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1, err
    assert err[0].startswith("sysid-nn: error:")
    assert "Traceback" not in err[0]
    return err[0]


@pytest.fixture(scope="module")
def quick_run(tmp_path_factory):
    out = tmp_path_factory.mktemp("cli") / "sysid_nn_results"
    status = main(
        ["reproduce", "--quick", "--n-test", "2", "--out", str(out), "--quiet"]
    )
    return status, out


def test_reproduce_quick_writes_everything(quick_run):
    status, out = quick_run
    assert status == 0
    assert {p.name for p in out.iterdir()} == {
        *FIGURES,
        "results.csv",
        "summary.csv",
        "report.md",
    }
    assert all((out / name).stat().st_size > 10_000 for name in FIGURES)
    results = pd.read_csv(out / "results.csv")
    assert set(results["realization"]) == {0, 1}
    assert {"nrmse", "fit_percent", "mean", "std", "whiteness_passed"} <= set(
        results.columns
    )
    report = (out / "report.md").read_text()
    assert "## Results at a glance" in report and "quick-run" in report


def test_reproduce_existing_output_needs_overwrite(quick_run, capsys):
    _, out = quick_run
    before = (out / "results.csv").read_bytes()
    assert main(["reproduce", "--quick", "--out", str(out)]) == 1
    line = _one_error_line(capsys)
    assert str(out) in line and "--overwrite" in line
    assert (out / "results.csv").read_bytes() == before


@pytest.mark.parametrize(
    ("args", "fragment"),
    [
        (["--n-test", "0"], "--n-test must be >= 1"),
        (["--training-records", "0"], "--training-records must be >= 1"),
        (["--seed", "-1"], "--seed must be >= 0"),
        (["--seed", str(2**32)], "--seed must be < 2**32"),
        (["--n-jobs", "0"], "--n-jobs must not be 0"),
    ],
)
def test_reproduce_bad_values_exit_2_with_one_line(tmp_path, capsys, args, fragment):
    out = tmp_path / "out"
    assert main(["reproduce", *args, "--out", str(out)]) == 2
    assert fragment in _one_error_line(capsys)
    assert not out.exists()


@pytest.mark.parametrize("args", [["--n-test", "x"], ["--quick", "extra"], ["--nope"]])
def test_reproduce_syntax_errors_exit_2(tmp_path, capsys, args):
    with pytest.raises(SystemExit) as exc:
        main(["reproduce", *args, "--out", str(tmp_path / "out")])
    assert exc.value.code == 2
    last = capsys.readouterr().err.strip().splitlines()[-1]
    assert last.startswith(("sysid-nn reproduce: error:", "sysid-nn: error:"))


def test_reproduce_unwritable_directory_one_line(tmp_path, capsys):
    blocker = tmp_path / "a_file"
    blocker.write_text("x")
    assert main(["reproduce", "--quick", "--out", str(blocker / "out")]) == 1
    line = _one_error_line(capsys)
    assert "cannot write" in line and str(blocker) in line


def test_reproduce_unreachable_scheduler_one_line(tmp_path, capsys):
    pytest.importorskip("dask.distributed")
    import dask

    with dask.config.set({"distributed.comm.timeouts.connect": "1s"}):
        status = main(
            [
                "reproduce",
                "--out",
                str(tmp_path / "out"),
                "--scheduler",
                "tcp://127.0.0.1:9",
                "--quiet",
            ]
        )
    assert status == 1
    assert "cannot connect to the dask scheduler" in _one_error_line(capsys)
    assert list(tmp_path.iterdir()) == []


# ------------------------------------------------------------ fit / validate
@pytest.fixture(scope="module")
def records(tmp_path_factory):
    """Two training files (one experiment each) and a generated multi-record file."""
    from sysid_nn import HystereticOscillator

    folder = tmp_path_factory.mktemp("records")
    rec = HystereticOscillator(r0=0.05).generate(
        4, n_samples=400, random_state=1, as_frame=True
    )
    frame = rec.frame.rename(columns={"excitation": "force"})
    paths = []
    for j in (0, 1):
        path = folder / f"exp{j}.csv"
        part = frame[frame["realization"] == j].drop(columns="realization")
        part.to_csv(path, index=False)
        paths.append(path)
    many = folder / "many.csv"
    frame[frame["realization"] >= 2].to_csv(many, index=False)
    return paths, many


TINY_FIT = ["--n-init", "1", "--max-iter", "5", "--dt", "0.01"]


@pytest.mark.filterwarnings("ignore::sklearn.exceptions.ConvergenceWarning")
def test_a_saved_ensemble_validates_as_its_median(records, tmp_path, capsys):
    from sysid_nn import EnsembleRegressor, TDLRegressor, load_model, save_model

    (a, b), many = records
    train = [pd.read_csv(path) for path in (a, b)]
    member = TDLRegressor(
        hidden_layer_sizes=(3,), output_lags=2, input_lags=2, n_init=1, max_iter=5
    )
    ensemble = EnsembleRegressor(member, n_members=3, random_state=0).fit(
        [f[["force"]].to_numpy() for f in train],
        [f["displacement"].to_numpy() for f in train],
    )
    model = tmp_path / "ensemble.sysid"
    save_model(ensemble, model, inputs=["force"], outputs=["displacement"], dt=0.01)
    loaded = load_model(model)
    assert type(loaded) is EnsembleRegressor
    # Every parameter, the member's (estimator__*) included, but the member
    # object itself (compared by identity).
    params = [{k: v for k, v in e.get_params().items() if k != "estimator"}
              for e in (loaded, ensemble)]  # fmt: skip
    assert params[0] == params[1] and "estimator__output_lags" in params[0]
    part = pd.read_csv(many).query("realization == 2")
    X, y = part[["force"]].to_numpy(), part["displacement"].to_numpy()
    np.testing.assert_array_equal(loaded.simulate(X), ensemble.simulate(X))
    np.testing.assert_array_equal(loaded.predict(X, y), ensemble.predict(X, y))
    for saved, member in zip(loaded.estimators_, ensemble.estimators_, strict=True):
        for w, v in zip(saved.coefs_, member.coefs_, strict=True):
            np.testing.assert_array_equal(w, v)
    # The command line validates it as the ensemble's median free run.
    out = tmp_path / "validation"
    argv = ["validate", "--model", str(model), str(many), "--split-by", "realization"]
    assert main([*argv, "--out", str(out), "--max-lag", "10", "--quiet"]) == 0
    row = pd.read_csv(out / "results.csv").query("record == 0 and mode == 'simulation'")
    rmse = np.sqrt(np.mean((y - ensemble.simulate(X)) ** 2))
    np.testing.assert_allclose(row["nrmse"].iloc[0], rmse / np.std(y), rtol=1e-10)
    report = (out / "report.md").read_text()
    # No modes of a median: the report says why and how to get one network.
    assert "the model is the median of 3 networks" in report
    assert "Fit it with distil=True" in report
    # Its parameters on one line of the models' table, its member's included.
    assert "output_lags=2), n_members=3 |" in report
    # Its median has no band: the command says so.
    argv += ["--out", str(tmp_path / "band"), "--band", "0.95", "--quiet"]
    assert main(argv) == 2
    assert "return_std" in capsys.readouterr().err


def test_fit_validate_round_trip_tdl(records, tmp_path, capsys):
    (a, b), many = records
    model = tmp_path / "model.sysid"
    argv = ["fit", str(a), str(b), "--input", "force", "--output", "displacement"]
    argv += ["--hidden", "3", "--output-lags", "2", "--input-lags", "2", *TINY_FIT]
    assert main([*argv, "--save", str(model)]) == 0
    assert "fitted TDL" in capsys.readouterr().out
    bundle = _read_bundle(model)
    assert bundle.model.inputs == ("force",) and bundle.dt == 0.01
    assert bundle.model.estimator.get_params()["hidden_layer_sizes"] == (3,)

    out = tmp_path / "validation"
    argv = ["validate", "--model", str(model), str(many), "--split-by", "realization"]
    assert main([*argv, "--out", str(out), "--max-lag", "10", "--quiet"]) == 0
    # The user's own figure names, not the paper's fig4_x numbering.
    figures = [name.split("_", 2)[2] for name in list(FIGURES)[1:7]]
    assert figures[0] == "prediction.png"
    expected = {*figures, "results.csv", "summary.csv", "report.md"}
    assert {p.name for p in out.iterdir()} == expected | {"series.csv"}
    results = pd.read_csv(out / "results.csv")
    assert sorted(set(results["record"])) == [0, 1]
    summary = pd.read_csv(out / "summary.csv")
    assert set(summary["model"]) == {bundle.model.label}
    # The saved model reproduces the validation numbers.
    est = bundle.model.estimator
    part = pd.read_csv(many).query("realization == 2")
    sim = est.simulate(part[["force"]].to_numpy())
    y = part["displacement"].to_numpy()
    row = results.query("record == 0 and mode == 'simulation'").iloc[0]
    rmse = np.sqrt(np.mean((y - sim) ** 2))
    np.testing.assert_allclose(row["nrmse"], rmse / np.std(y), rtol=1e-10)
    # The series file holds what was scored, for the user's own tools.
    series = pd.read_csv(out / "series.csv").query("record == 0")
    np.testing.assert_allclose(series["displacement_simulated"], sim, rtol=1e-9)
    np.testing.assert_allclose(series["force"], part["force"])
    pred = est.predict(part[["force"]].to_numpy(), y)
    np.testing.assert_allclose(series["displacement_predicted"], pred, rtol=1e-9)
    np.testing.assert_allclose(series["t"], 0.01 * np.arange(len(y)))
    report = (out / "report.md").read_text()
    assert "## Results at a glance" in report and "`series.csv`" in report
    # The modes of the model and its non-linearity verdict on these records.
    assert "## The structure" in report and "| mode | frequency [Hz] |" in report
    assert "Non-linearity test on these records: The network" in report
    # The user's own test, in the user's words: no paper's sections or symbols.
    own = report.replace("split by 'realization'", "")  # the user's column
    for paper in ("section 4.", "eq. 19", "N_s", "realisation", "realization"):
        assert paper not in own, paper
    for paper in ("μ_", "σ_", "fig4_", "fig. 4", "figs 4"):
        assert paper not in own, paper
    assert "![Mean error and error std of prediction errors](" in report
    assert "The model's one-step residuals" in report
    assert "Some models'" not in report
    # Loading the saved model in Python is one public call.
    from sysid_nn import load_model

    loaded, info = load_model(model, with_info=True)
    np.testing.assert_array_equal(loaded.simulate(part[["force"]].to_numpy()), sim)
    assert info.inputs == ("force",) and info.outputs == ("displacement",)
    assert type(load_model(model)) is type(est)


@pytest.mark.filterwarnings("ignore::sklearn.exceptions.ConvergenceWarning")
@pytest.mark.filterwarnings("ignore::sklearn.exceptions.ConvergenceWarning")
def test_fit_refit_continues_on_the_validation_records(records, tmp_path, capsys):
    from sysid_nn import TDLRegressor, load_model

    (a, b), _ = records
    model = tmp_path / "refit.sysid"
    argv = ["fit", str(a), "--input", "force", "--output", "displacement"]
    argv += ["--hidden", "3", *TINY_FIT, "--val", str(b), "--refit"]
    assert main([*argv, "--save", str(model)]) == 0
    assert "refit=True" in capsys.readouterr().out
    loaded = load_model(model)
    # The fit a user would get in Python with refit=True.
    net = TDLRegressor(
        hidden_layer_sizes=(3,), n_init=1, max_iter=5, refit=True, random_state=0
    )
    train, val = pd.read_csv(a), pd.read_csv(b)
    same = net.fit(
        train[["force"]].to_numpy(),
        train["displacement"].to_numpy(),
        X_val=val[["force"]].to_numpy(),
        y_val=val["displacement"].to_numpy(),
    )
    assert loaded.refit and loaded.refit_steps_ == same.refit_steps_
    np.testing.assert_array_equal(loaded.refit_losses_, same.refit_losses_)
    np.testing.assert_array_equal(loaded.coefs_, same.coefs_)


def test_fit_members_saves_the_median_of_their_fits(records, tmp_path, capsys):
    from sysid_nn import EnsembleRegressor, TDLRegressor, load_model

    (a, b), many = records
    model = tmp_path / "ensemble.sysid"
    argv = ["fit", str(a), "--input", "force", "--output", "displacement"]
    argv += ["--hidden", "3", *TINY_FIT, "--members", "3", "--seed", "4"]
    assert main([*argv, "--save", str(model)]) == 0
    out = capsys.readouterr().out
    assert "each member's own last 15%-25% of" in out
    loaded = load_model(model)
    # The label counts the members that entered the median (these tiny fits
    # differ: some miss the record far worse than the best one).
    used = int(loaded.members_used_.sum())
    assert 1 <= used < 3
    what = (
        f"median of {used} of 3 × TDL (hidden_layer_sizes=(3,), n_init=1, max_iter=5)"
    )
    assert f"fitted {what} in" in out
    label = _read_bundle(model).model.label
    assert type(loaded) is EnsembleRegressor and label == what
    # The members a user would get from EnsembleRegressor in Python: their
    # seeds drawn from --seed, each holding out its own share of the record.
    assert loaded.member_validation_fractions_ == [0.15, 0.2, 0.25]
    net = TDLRegressor(hidden_layer_sizes=(3,), n_init=1, max_iter=5, verbose=0)
    frame = pd.read_csv(a)
    X, y = frame[["force"]].to_numpy(), frame["displacement"].to_numpy()
    same = EnsembleRegressor(net, n_members=3, random_state=4).fit(X, y)
    assert loaded.member_random_states_ == same.member_random_states_
    np.testing.assert_array_equal(loaded.members_used_, same.members_used_)
    np.testing.assert_allclose(loaded.simulate(X), same.simulate(X), rtol=1e-10)
    # With validation records every member validates on them.
    other = tmp_path / "with_val.sysid"
    argv = ["fit", str(a), "--val", str(b), "--input", "force", "--output"]
    argv += ["displacement", "--hidden", "3", *TINY_FIT, "--members", "2"]
    assert main([*argv, "--save", str(other), "--quiet"]) == 0
    assert load_model(other).member_validation_fractions_ == [None, None]
    # `validate` scores the median, as saved.
    report = tmp_path / "validation"
    argv = ["validate", "--model", str(model), str(many), "--split-by", "realization"]
    assert main([*argv, "--out", str(report), "--max-lag", "10", "--quiet"]) == 0
    summary = pd.read_csv(report / "summary.csv")
    assert set(summary["model"]) == {label}
    # Modes belong to one network: the median has none, and says so.
    capsys.readouterr()
    assert main(["modal", str(model)]) == 1
    assert "median of 3 networks" in _one_error_line(capsys)


def test_fit_distil_needs_members(records, tmp_path, capsys):
    (a, _), _ = records
    model = tmp_path / "model.sysid"
    argv = ["fit", str(a), "--input", "force", "--output", "displacement"]
    assert main([*argv, *TINY_FIT, "--distil", "--save", str(model)]) == 2
    line = _one_error_line(capsys)
    assert "--distil" in line and "--members N with N of at least 2" in line
    assert not model.exists()


def test_fit_with_validation_files(records, tmp_path, capsys):
    (a, b), _ = records
    model = tmp_path / "model.sysid"
    argv = ["fit", str(a), "--val", str(b), "--input", "force"]
    argv += ["--output", "displacement", "--hidden", "3", *TINY_FIT]
    assert main([*argv, "--save", str(model)]) == 0
    assert "on 1 experiment(s)" in capsys.readouterr().out
    estimator = _read_bundle(model).model.estimator
    # The validation file selected the weights.
    assert estimator.best_validation_score_ is not None
    missing = ["fit", str(a), "--val", str(tmp_path / "none.csv"), "--input", "force"]
    missing += ["--output", "displacement", "--save", str(tmp_path / "other.sysid")]
    assert main(missing) == 1
    assert "none.csv" in _one_error_line(capsys)


def test_fit_issm_two_outputs(records, tmp_path, capsys):
    (a, _), _ = records
    model = tmp_path / "issm.sysid"
    argv = ["fit", str(a), "--input", "force", "--output", "displacement"]
    argv += ["--output", "velocity", "--model", "issm", "--n-states", "3", *TINY_FIT]
    assert main([*argv, "--save", str(model)]) == 0
    est = _read_bundle(model).model.estimator
    assert est.n_outputs_ == 2 and est.n_states_ == 3
    capsys.readouterr()


@pytest.mark.parametrize(
    ("extra", "fragment"),
    [
        (
            ["--output", "displacement", "--model", "tdl", "--n-states", "3"],
            "--n-states",
        ),
        (
            ["--output", "displacement", "--model", "issm", "--input-lags", "2"],
            "--input-lags",
        ),
    ],
)
def test_fit_bad_arguments_exit_2(records, tmp_path, capsys, extra, fragment):
    (a, _), _ = records
    argv = ["fit", str(a), "--input", "force", *extra, "--save", str(tmp_path / "m")]
    assert main(argv) == 2
    assert fragment in _one_error_line(capsys)
    assert not (tmp_path / "m").exists()


def test_fit_syntax_errors_exit_2(records, tmp_path, capsys):
    (a, _), _ = records
    for bad in (["--hidden", "x"], ["--model", "rnn"], ["--dt", "0"]):
        with pytest.raises(SystemExit) as exc:
            main(
                [
                    "fit",
                    str(a),
                    "--input",
                    "force",
                    "--output",
                    "displacement",
                    *bad,
                    "--save",
                    str(tmp_path / "m"),
                ]
            )
        assert exc.value.code == 2
    with pytest.raises(SystemExit):
        main(
            [
                "fit",
                str(tmp_path / "data.txt"),
                "--input",
                "f",
                "--output",
                "y",
                "--save",
                "m",
            ]
        )
    capsys.readouterr()


def test_missing_files_exit_1_with_one_line(records, tmp_path, capsys):
    argv = ["fit", str(tmp_path / "none.csv"), "--input", "force", "--output", "x"]
    assert main([*argv, "--save", str(tmp_path / "m")]) == 1
    assert "cannot read" in _one_error_line(capsys)
    junk = tmp_path / "junk.sysid"
    junk.write_text("not a model")
    (a, _), _ = records
    argv = ["validate", "--model", str(junk), str(a), "--out", str(tmp_path / "v")]
    assert main(argv) == 1
    assert "is not a model file" in _one_error_line(capsys)
    assert not (tmp_path / "v").exists()


def test_validate_reports_predictions_that_turn_non_finite(records, tmp_path, capsys):
    (a, b), _ = records
    model = tmp_path / "model.sysid"
    argv = ["fit", str(a), "--input", "force", "--output", "displacement"]
    argv += ["--hidden", "0", "--output-lags", "2", "--input-lags", "2", *TINY_FIT]
    assert main([*argv, "--save", str(model), "--quiet"]) == 0
    # A glitch in the measured output at sample 231: the one-step predictor,
    # fed the measurement, leaves the range from the next sample on.
    glitch = tmp_path / "glitch.csv"
    frame = pd.read_csv(b)
    frame.loc[231, "displacement"] = 1e12
    frame.to_csv(glitch, index=False)
    out = tmp_path / "validation"
    argv = ["validate", "--model", str(model), str(glitch), "--max-lag", "10"]
    assert main([*argv, "--out", str(out), "--quiet"]) == 0
    err = capsys.readouterr().err
    assert (
        "warning: The one-step predictions of 'displacement' on "
        f"{glitch} are not finite from sample 232" in err
    )
    assert "free run" not in err  # the free run does not read the outputs
    report = (out / "report.md").read_text()
    assert "## Warnings" in report
    assert "on record 0 are not finite from sample 232" in report
    # A clean record: no warning.
    assert main([*argv[:3], str(b), *argv[4:], "--out", str(out), "--overwrite"]) == 0
    assert "not finite" not in capsys.readouterr().err


def test_validate_starts_free_runs_from_measured_samples(tmp_path, capsys):
    from scipy.signal import lfilter

    from sysid_nn import load_model

    rng = np.random.default_rng(3)
    u = rng.standard_normal(1200)
    y = lfilter([0.0, 0.5], [1.0, -1.8, 0.9], u) + 1e-3 * rng.standard_normal(1200)
    t = 0.01 * np.arange(600)
    train, moving = tmp_path / "train.csv", tmp_path / "moving.csv"
    pd.DataFrame({"t": t, "force": u[:600], "x": y[:600]}).to_csv(train, index=False)
    # A record that starts in motion: the continuation, cut mid-motion.
    frame = pd.DataFrame({"t": t[:300], "force": u[900:], "x": y[900:]})
    frame.to_csv(moving, index=False)
    model = tmp_path / "model.sysid"
    argv = ["fit", str(train), "--input", "force", "--output", "x", "--hidden", "0"]
    argv += ["--output-lags", "2", "--input-lags", "1", "--n-init", "1"]
    assert main([*argv, "--save", str(model), "--quiet"]) == 0
    argv = ["validate", "--model", str(model), str(moving), "--max-lag", "10"]
    runs = {}
    for extra in ([], ["--y-init", "40"]):
        out = tmp_path / f"v{len(extra)}"
        assert main([*argv, *extra, "--out", str(out)]) == 0
        printed = capsys.readouterr().out
        results = pd.read_csv(out / "results.csv").set_index("mode")
        runs[len(extra)] = results.loc["simulation", "nrmse"]
        report = (out / "report.md").read_text()
        if extra:
            assert "free runs from their first 40 measured samples" in printed
            assert "Free runs start from each record's first 40 measured" in report
        else:
            assert "free runs from rest" in printed
            assert "Free runs start from rest" in report
    # The measured start, scored after the window, as simulate(y_init=...) is.
    est = load_model(model)
    X, y = frame[["force"]].to_numpy(), frame["x"].to_numpy()
    sim = est.simulate(X, y_init=y[:40])
    expected = np.sqrt(np.mean((y[40:] - sim[40:]) ** 2)) / np.std(y[40:])
    np.testing.assert_allclose(runs[2], expected, rtol=1e-10)
    # From rest the run carries the unknown start's transient; not from the window.
    assert runs[2] < 0.01 < runs[0]
    # The window must leave room for the residual tests.
    assert main([*argv, "--y-init", "290", "--out", str(tmp_path / "v9")]) == 2
    assert "after the first 290 (--y-init)" in _one_error_line(capsys)
