"""The ``sysid-nn`` command and the user's files: overwriting, data loss,
sample times, columns, units, progress and exit statuses."""

import argparse
import io
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from sysid_nn import HystereticOscillator
from sysid_nn._saved import _read_bundle
from sysid_nn.cli import build_parser, main

TINY = ["--n-init", "1", "--max-iter", "3", "--hidden", "2"]
TINY += ["--output-lags", "2", "--input-lags", "2"]


def _error(capsys):
    """The one error line on stderr (and nothing else: no progress, no traceback)."""
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1, err
    assert err[0].startswith("sysid-nn: error:")
    return err[0]


@pytest.fixture(scope="module")
def frame():
    rec = HystereticOscillator(r0=0.05).generate(
        3, n_samples=300, dt=0.02, random_state=2, as_frame=True
    )
    return rec.frame.rename(columns={"excitation": "force"})


@pytest.fixture
def files(tmp_path, frame):
    """Three one-experiment files with a time column ``t`` (dt = 0.02 s)."""
    paths = []
    for j in range(3):
        path = tmp_path / f"exp{j}.csv"
        frame[frame.realization == j].drop(columns="realization").to_csv(
            path, index=False
        )
        paths.append(path)
    return paths


def _fit(files, save, *extra):
    argv = ["fit", *map(str, files), "--input", "force", "--output", "displacement"]
    return main([*argv, *TINY, *extra, "--save", str(save)])


# ------------------------------------------------------------ overwriting
def test_fit_never_saves_over_its_own_data(files, tmp_path, capsys):
    data = files[0]
    before = data.read_bytes()
    for save in (data, tmp_path / "sub" / ".." / data.name):
        (tmp_path / "sub").mkdir(exist_ok=True)
        for extra in ([], ["--overwrite"]):
            assert _fit(files[:2], save, *extra) == 1
            line = _error(capsys)
            assert "would overwrite the input file" in line and data.name in line
    assert _fit(files[:1], tmp_path / "m.sysid", "--val", str(files[1])) == 0
    capsys.readouterr()
    assert _fit(files[:1], files[1], "--val", str(files[1]), "--overwrite") == 1
    assert "would overwrite the input file" in _error(capsys)
    assert data.read_bytes() == before


def test_fit_save_needs_overwrite(files, tmp_path, capsys):
    save = tmp_path / "model.sysid"
    save.write_text("precious")
    assert _fit(files[:2], save) == 1
    line = _error(capsys)
    assert str(save) in line and "--overwrite" in line
    assert save.read_text() == "precious"
    # --overwrite replaces a model file only, never data or anything else.
    assert _fit(files[:2], save, "--overwrite", "--quiet") == 1
    line = _error(capsys)
    assert "is not a model file" in line and "another --save" in line
    assert save.read_text() == "precious"
    model = tmp_path / "m.sysid"
    assert _fit(files[:2], model, "--quiet") == 0
    assert _fit(files[:2], model, "--overwrite", "--quiet", "--seed", "1") == 0
    assert _read_bundle(model).model.estimator.random_state == 1
    assert _read_bundle(model).model.inputs == ("force",)
    assert [p.name for p in tmp_path.glob(".m.sysid*")] == []


def test_generate_needs_overwrite_and_writes_atomically(tmp_path, capsys, monkeypatch):
    out = tmp_path / "records.csv"
    small = ["generate", "--n-realizations", "1", "--n-samples", "50", "--r0", "0.05"]
    assert main([*small, "--out", str(out)]) == 0
    first = out.read_bytes()
    assert main([*small, "--seed", "1", "--out", str(out)]) == 1
    assert "--overwrite" in _error(capsys)
    assert out.read_bytes() == first

    def broken(self, path, **kwargs):
        with open(path, "w") as f:
            f.write("half a tab")
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(pd.DataFrame, "to_csv", broken)
    assert main([*small, "--seed", "1", "--out", str(out), "--overwrite"]) == 1
    assert "No space left on device" in _error(capsys)
    assert out.read_bytes() == first  # the old file, whole
    assert sorted(p.name for p in tmp_path.iterdir()) == ["records.csv"]
    monkeypatch.undo()
    assert main([*small, "--seed", "1", "--out", str(out), "--overwrite"]) == 0
    assert out.read_bytes() != first


def test_unwritable_save_is_refused_before_fitting(files, tmp_path, capsys):
    blocker = tmp_path / "a_file"
    blocker.write_text("x")
    for save in (tmp_path / "no_such_dir" / "m.sysid", blocker / "m.sysid"):
        assert _fit(files[:2], save) == 1
        # One line: the error, and no training progress before it.
        line = _error(capsys)
        assert "cannot write" in line and str(save) in line


def test_validate_out_never_replaces_inputs_or_foreign_folders(files, tmp_path, capsys):
    model = tmp_path / "m.sysid"
    assert _fit(files[:2], model, "--quiet") == 0
    capsys.readouterr()  # the short fit's convergence warning
    argv = ["validate", "--model", str(model), str(files[2]), "--max-lag", "5"]
    # --out is the folder holding the data and the model: refused, even with
    # --overwrite, and everything is still there.
    assert main([*argv, "--out", str(tmp_path), "--overwrite", "--quiet"]) == 1
    assert "would overwrite the input file" in _error(capsys)
    assert all(p.exists() for p in [model, *files])
    # A folder of other files is not an output: --overwrite does not empty it.
    other = tmp_path / "photos"
    other.mkdir()
    (other / "holiday.jpg").write_bytes(b"\xff")
    assert main([*argv, "--out", str(other), "--overwrite", "--quiet"]) == 1
    assert "no report.md" in _error(capsys)
    assert (other / "holiday.jpg").exists()
    out = tmp_path / "validation"
    assert main([*argv, "--out", str(out), "--quiet"]) == 0
    assert main([*argv, "--out", str(out), "--quiet"]) == 1
    assert "--overwrite" in _error(capsys)
    assert main([*argv, "--out", str(out), "--overwrite", "--quiet"]) == 0
    assert (out / "report.md").is_file()


# ----------------------------------------------------------- sample times
def test_dt_is_inferred_from_the_time_column(files, tmp_path, capsys):
    save = tmp_path / "m.sysid"
    assert _fit(files[:2], save) == 0
    assert "dt = 0.02 s" in capsys.readouterr().out
    assert _read_bundle(save).dt == pytest.approx(0.02)
    # --dt that disagrees with the file is an error, not a silent choice.
    assert _fit(files[:2], tmp_path / "m2.sysid", "--dt", "0.01") == 1
    line = _error(capsys)
    assert "--dt 0.01" in line and "'t'" in line and "0.02" in line
    assert _fit(files[:2], tmp_path / "m3.sysid", "--dt", "0.02", "--quiet") == 0


def test_no_time_column_needs_dt(files, tmp_path, capsys):
    bare = tmp_path / "bare.csv"
    pd.read_csv(files[0]).drop(columns="t").to_csv(bare, index=False)
    assert _fit([bare], tmp_path / "m.sysid") == 2
    line = _error(capsys)
    assert "bare.csv" in line and "--dt" in line
    assert _fit([bare], tmp_path / "m.sysid", "--dt", "0.02", "--quiet") == 0


def test_non_uniform_times_are_an_error(files, tmp_path, capsys):
    gappy = tmp_path / "gappy.csv"
    frame = pd.read_csv(files[0])
    frame.drop(index=[100, 101]).to_csv(gappy, index=False)
    assert _fit([gappy], tmp_path / "m.sysid") == 1
    line = _error(capsys)
    assert "gappy.csv" in line and "'t'" in line and "not uniform" in line


def test_forgotten_split_by_is_detected(frame, tmp_path, capsys):
    table = tmp_path / "records.csv"
    frame.to_csv(table, index=False)
    argv = ["fit", str(table), "--input", "force", "--output", "displacement"]
    assert main([*argv, *TINY, "--save", str(tmp_path / "m.sysid")]) == 1
    line = _error(capsys)
    assert "restarts" in line and "--split-by realization" in line
    argv += ["--split-by", "realization", "--quiet"]
    assert main([*argv, *TINY, "--save", str(tmp_path / "m.sysid")]) == 0


# ------------------------------------------------------ the user's own files
def test_semicolons_and_decimal_commas_are_read(files, tmp_path, capsys):
    lab = tmp_path / "lab.csv"
    pd.read_csv(files[0]).to_csv(lab, index=False, sep=";", decimal=",")
    assert "0,02;" in lab.read_text().splitlines()[2]  # a lab export, really
    save = tmp_path / "m.sysid"
    assert _fit([lab], save, "--quiet") == 0  # sniffed
    assert _read_bundle(save).dt == pytest.approx(0.02)
    argv = ["--quiet", "--overwrite", "--sep", ";", "--decimal", ","]
    assert _fit([lab], save, *argv) == 0
    capsys.readouterr()
    # Told the wrong decimal mark: the error says which option reads the file.
    assert _fit([lab], save, "--overwrite", "--decimal", ".") == 1
    line = _error(capsys)
    assert "lab.csv" in line and "--decimal ','" in line


def test_datetime_time_column_suggests_dt(files, tmp_path, capsys):
    stamped = tmp_path / "stamped.csv"
    frame = pd.read_csv(files[0])
    start = pd.Timestamp("2026-01-01 10:00:00")
    frame["t"] = start + pd.to_timedelta(frame["t"], unit="s")
    frame.to_csv(stamped, index=False)
    assert _fit([stamped], tmp_path / "m.sysid") == 1
    line = _error(capsys)
    assert "dates and times" in line and "--time-column none --dt 0.02" in line


def test_descending_time_column_is_not_taken_for_experiments(files, tmp_path, capsys):
    backwards = tmp_path / "backwards.csv"
    pd.read_csv(files[0]).iloc[::-1].to_csv(backwards, index=False)
    assert _fit([backwards], tmp_path / "m.sysid") == 1
    line = _error(capsys)
    assert "runs backwards" in line and "sort the file by time" in line
    assert "--split-by" not in line


def test_duplicated_header_names_are_rejected(files, tmp_path, capsys):
    twice = tmp_path / "twice.csv"
    frame = pd.read_csv(files[0])
    frame.insert(2, "force2", frame["force"])
    text = frame.to_csv(index=False).replace("force2", "force", 1)
    twice.write_text(text)
    assert _fit([twice], tmp_path / "m.sysid") == 1
    line = _error(capsys)
    assert "twice.csv" in line and "'force' more than once" in line


def test_an_input_that_never_changes_is_rejected(files, tmp_path, capsys):
    paths = []
    for k, path in enumerate(files[:2]):
        paths.append(tmp_path / f"zero{k}.csv")
        pd.read_csv(path).assign(force=0.0).to_csv(paths[-1], index=False)
    assert _fit(paths, tmp_path / "m.sysid") == 1
    line = _error(capsys)
    assert "input column 'force' holds the single value 0" in line
    assert not (tmp_path / "m.sysid").exists()


def test_an_output_that_never_changes_is_rejected(files, tmp_path, capsys):
    flat = tmp_path / "flat.csv"
    pd.read_csv(files[0]).assign(displacement=1.5).to_csv(flat, index=False)
    assert _fit([flat], tmp_path / "m.sysid") == 1
    line = _error(capsys)
    assert "output column 'displacement' holds the single value 1.5" in line
    assert "--output" in line and not (tmp_path / "m.sysid").exists()


def test_records_too_short_for_the_model_are_rejected(files, tmp_path, capsys):
    short = tmp_path / "short.csv"
    pd.read_csv(files[0]).head(10).to_csv(short, index=False)
    # 10 rows, 2 output and 2 input lags, 2 hidden units: 8 modelled samples
    # for 17 weights (found once the fit has resolved the structure).
    assert _fit([short], tmp_path / "m.sysid", "--quiet") == 1
    line = _error(capsys)
    assert "too short for the model: 8 modelled output sample(s)" in line
    assert "for 17 weights" in line and not (tmp_path / "m.sysid").exists()
    # The linear model with one lag of each (3 weights) fits them.
    linear = ["--hidden", "0", "--output-lags", "1", "--input-lags", "1"]
    assert _fit([short], tmp_path / "m.sysid", *linear, "--quiet") == 0


def test_help_shows_every_default(capsys):
    parser = build_parser()
    (commands,) = [
        a.choices for a in parser._actions if isinstance(a, argparse._SubParsersAction)
    ]
    for command in ("generate", "reproduce", "fit", "validate"):
        with pytest.raises(SystemExit):
            parser.parse_args([command, "--help"])
        text = " ".join(capsys.readouterr().out.split())
        for action in commands[command]._actions:
            if (
                action.default not in (None, "==SUPPRESS==", [])
                and action.default is not False
            ):
                assert f"default: {action.default}" in text, (command, action.dest)
    with pytest.raises(SystemExit):
        parser.parse_args(["fit", "--help"])
    text = " ".join(capsys.readouterr().out.split())
    assert "default: inferred from the files' time column" in text


# ---------------------------------------------------------------- columns
@pytest.mark.parametrize(
    "extra",
    [
        ["--input", "force", "--output", "force"],
        ["--input", "force", "--input", "force", "--output", "displacement"],
        ["--input", "force", "--output", "displacement", "--split-by", "force"],
    ],
)
def test_one_column_one_role(files, tmp_path, capsys, extra):
    argv = ["fit", str(files[0]), *extra, "--save", str(tmp_path / "m")]
    assert main(argv) == 2
    assert "'force'" in _error(capsys)
    assert not (tmp_path / "m").exists()


@pytest.mark.parametrize(
    ("change", "fragment"),
    [
        (lambda f: f.drop(columns="force"), "no column(s) 'force'"),
        (
            lambda f: f.assign(force=f.force.astype(object).where(f.t != 1, "abc")),
            "'abc'",
        ),
        (
            lambda f: f.assign(displacement=f.displacement.where(f.t != 1)),
            "'displacement'",
        ),
    ],
)
def test_file_content_errors_exit_1_naming_file_and_column(
    files, tmp_path, capsys, change, fragment
):
    bad = tmp_path / "bad.csv"
    change(pd.read_csv(files[0])).to_csv(bad, index=False)
    assert _fit([bad], tmp_path / "m.sysid") == 1
    line = _error(capsys)
    assert "bad.csv" in line and fragment in line


# ---------------------------------------------------- validate, many outputs
def test_validate_reports_every_output_with_units(frame, tmp_path, capsys, monkeypatch):
    named = frame.rename(
        columns={"displacement": "displacement [m]", "velocity": "velocity (m/s)"}
    )
    table = tmp_path / "records.csv"
    named.to_csv(table, index=False)
    model = tmp_path / "m.sysid"
    argv = ["fit", str(table), "--split-by", "realization", "--input", "force"]
    argv += ["--output", "displacement [m]", "--output", "velocity (m/s)"]
    argv += ["--model", "issm", "--n-init", "1", "--max-iter", "3"]
    assert main([*argv, "--units", "force=kN", "--save", str(model)]) == 0
    assert _read_bundle(model).units == {
        "force": "kN",
        "displacement [m]": "m",
        "velocity (m/s)": "m/s",
    }
    printed = capsys.readouterr().out
    assert "displacement [m]: prediction NRMSE" in printed
    assert "velocity (m/s): prediction NRMSE" in printed

    out = tmp_path / "validation"
    argv = ["validate", "--model", str(model), str(table), "--split-by", "realization"]
    drawn = _figure_texts(monkeypatch)
    assert main([*argv, "--out", str(out), "--max-lag", "5"]) == 0
    captured = capsys.readouterr()
    printed = captured.out
    lines = [line for line in printed.splitlines() if "NRMSE" in line and ":" in line]
    assert [line.split(":")[0].strip() for line in lines[1:]] == [
        "displacement [m]",
        "velocity (m/s)",
    ]
    assert "RMSE" in lines[1] and " m)" in lines[1] and " m/s)" in lines[2]
    assert "displacement" not in printed.replace("displacement [m]", "")
    # The report's steps show progress as plain lines (stderr is not a terminal).
    assert "evaluating: 3/3" in captured.err and "\r" not in captured.err

    # Report and tables: every output under its column name, with its unit.
    report = (out / "report.md").read_text()
    rows = [line for line in report.splitlines() if line.startswith("| ISSM")]
    outputs = [line.split(" | ")[1] for line in rows if "ISSMRegressor" not in line]
    assert outputs == 3 * ["displacement [m]", "velocity (m/s)"]  # glance, 4.3, 4.4
    assert "displacement [m] and velocity (m/s)" in report
    assert "[m] [m]" not in report and "sim. / linear" not in report
    assert "realisation" not in report
    summary = pd.read_csv(out / "summary.csv")
    assert sorted(set(summary["output"])) == ["displacement [m]", "velocity (m/s)"]
    assert (
        len(pd.read_csv(out / "results.csv")) == 3 * 2 * 2
    )  # records x outputs x modes

    # Figures: both outputs on the axes, units once, the input by its name.
    # The user's figure names, and no paper's notation drawn in them.
    for name in (
        "prediction.png",
        "residual_autocorrelation.png",
        "residual_cross_correlation.png",
        "prediction_error_statistics.png",
        "simulation.png",
        "simulation_error_statistics.png",
    ):
        text = " ".join(drawn[name])
        assert "displacement [m]" in text and "velocity (m/s)" in text, name
        assert "[m] [m]" not in text and "input 0" not in text, name
        assert "μ_" not in text and "σ_" not in text and "fig. 4" not in text, name
    assert "force [kN]" in drawn["residual_cross_correlation.png"]
    assert "error [m/s]" in drawn["simulation_error_statistics.png"]
    assert "mean error" in drawn["simulation_error_statistics.png"]
    assert "record 0" in " ".join(drawn["prediction.png"])


def _figure_texts(monkeypatch):
    """Record every title, axis label and legend text of the figures saved."""
    from matplotlib.figure import Figure

    drawn = {}
    savefig = Figure.savefig

    def recording(fig, fname, *args, **kwargs):
        texts = [fig._suptitle.get_text()] if fig._suptitle else []
        for ax in fig.axes:
            texts += [ax.get_title(), ax.get_xlabel(), ax.get_ylabel()]
            legend = ax.get_legend()
            texts += [t.get_text() for t in legend.get_texts()] if legend else []
        drawn[Path(fname).name] = texts
        return savefig(fig, fname, *args, **kwargs)

    monkeypatch.setattr(Figure, "savefig", recording)
    return drawn


def test_validate_max_lag_is_checked_against_the_records(tmp_path, capsys):
    rec = HystereticOscillator(r0=0.05).generate(
        2, n_samples=1000, random_state=4, as_frame=True
    )
    table = tmp_path / "long.csv"
    rec.frame.to_csv(table, index=False)
    model = tmp_path / "m.sysid"
    argv = ["fit", str(table), "--split-by", "realization", "--input", "excitation"]
    argv += ["--output", "displacement", *TINY, "--quiet"]
    assert main([*argv, "--save", str(model)]) == 0
    argv = ["validate", "--model", str(model), str(table), "--split-by", "realization"]
    # 400 lags fit 1000-sample records (the study's own records are 2000 long,
    # seen every third sample by the paper's TDL: that is not the user's case).
    out = tmp_path / "v"
    assert main([*argv, "--max-lag", "400", "--out", str(out), "--quiet"]) == 0
    capsys.readouterr()
    assert "max_lag=400" in (out / "report.md").read_text()
    assert main([*argv, "--max-lag", "600", "--out", str(tmp_path / "w")]) == 2
    line = _error(capsys)
    assert "--max-lag 600" in line and "1000" in line and "--max-lag 495" in line


# --------------------------------------------------------------- progress
def test_fit_progress_lines_and_closing_line(files, tmp_path, capsys):
    argv = ["--n-init", "2", "--focus", "simulation"]
    assert _fit(files, tmp_path / "m.sysid", *argv) == 0
    captured = capsys.readouterr()
    stages = [line for line in captured.err.splitlines() if "restart" in line]
    assert any("restart 1/2 stage 1/" in line for line in stages)
    assert any("restart 2/2" in line for line in stages)
    assert "\r" not in captured.err
    closing = captured.out.splitlines()
    assert (
        "trained on 2 experiment(s), weights chosen by early stopping on "
        "1 experiment(s)" in closing[0]
    )
    # The validation records chose the weights: not called held-out.
    assert "held-out" not in captured.out and "optimistic" in closing[0]
    assert "exp2.csv" in closing[0] and "R^2" not in captured.out
    assert closing[1].strip().startswith("displacement: prediction NRMSE")
    assert _fit(files, tmp_path / "q.sysid", "--quiet") == 0
    # Quiet: no progress, no summary; only warnings are left, one line each.
    quiet = capsys.readouterr()
    assert quiet.out == ""
    assert all(line.startswith("sysid-nn: warning:") for line in quiet.err.splitlines())


def test_fit_single_record_scores_its_held_out_tail(files, tmp_path, capsys):
    assert _fit(files[:1], tmp_path / "m.sysid") == 0
    out = capsys.readouterr().out
    assert "trained on 1 experiment(s), weights chosen by early stopping on " in out
    assert "on the last 20% of" in out and "held-out" not in out


def test_progress_survives_parallel_restarts(files, tmp_path, capsys):
    argv = ["--n-init", "2", "--n-jobs", "2", "--verbose"]
    assert _fit(files, tmp_path / "m.sysid", *argv) == 0
    assert "early stopping on 1 experiment(s)" in capsys.readouterr().out


def test_progress_bar_on_a_terminal(monkeypatch):
    from sysid_nn import TDLRegressor
    from sysid_nn._engine._progress import report_stage

    class Terminal(io.StringIO):
        def isatty(self):
            return True

    screen = Terminal()
    monkeypatch.setattr("sys.stderr", screen)
    est = TDLRegressor(verbose=True)
    for stage in range(3):
        report_stage(est, (0, 1), (stage, 3), "segment 1", 4, lambda: 0.5, 0.25)
    text = screen.getvalue()
    assert "TDLRegressor restart 1/1" in text and "3/3" in text
    assert "\r" in text  # a bar redrawn in place, on a terminal only
    silent = TDLRegressor(verbose=False)
    report_stage(silent, (0, 1), (0, 3), "segment 1", 4, lambda: 1 / 0, 0.25)
    assert screen.getvalue() == text  # nothing, and the loss is not computed


@pytest.mark.filterwarnings("ignore::sklearn.exceptions.ConvergenceWarning")
def test_progress_lines_within_a_long_stage(monkeypatch, capsys):
    from sysid_nn import TDLRegressor

    rec = HystereticOscillator().generate(1, 600, random_state=0)
    X, y = rec.excitation[0][:, None], rec.displacement[0]
    est = TDLRegressor(n_init=1, max_iter=6, shooting_segments=(), random_state=0)
    monkeypatch.setattr("sysid_nn._engine._progress.STEP_SECONDS", 0.0)
    est.set_params(verbose=1).fit(X, y)
    out = capsys.readouterr().err.splitlines()
    # The restart's lines, before the linear model's refinement starts.
    end = next(k for k, x in enumerate(out) if "restart 1/1 stage 2/2" in x)
    assert "refinement of the linear model stage 2/2" in out[-1]
    lines = [x for x in out[:end] if "training:" in x]
    steps = [int(x.split("training: ")[1].split()[0]) for x in lines]
    # One line per accepted step when every step is late enough, counted on.
    assert steps == list(range(1, len(steps) + 1)) and len(steps) >= 2
    assert all("best validation" in x for x in lines)
    monkeypatch.setattr("sysid_nn._engine._progress.STEP_SECONDS", 3600.0)
    est.fit(X, y)
    assert "training:" not in capsys.readouterr().err
    est.set_params(verbose=0)
    monkeypatch.setattr("sysid_nn._engine._progress.STEP_SECONDS", 0.0)
    est.fit(X, y)
    assert capsys.readouterr().err == ""


def test_study_progress_is_plain_lines_off_a_terminal(monkeypatch):
    from sysid_nn.study._progress import _progress

    class Terminal(io.StringIO):
        def isatty(self):
            return True

    for stream, bar in ((io.StringIO(), False), (Terminal(), True)):
        monkeypatch.setattr("sys.stderr", stream)
        assert list(_progress(iter("abc"), 3, "figures", True)) == ["a", "b", "c"]
        text = stream.getvalue()
        assert ("\r" in text) == bar, text
        if not bar:
            lines = text.splitlines()
            assert [line.split(" (")[0] for line in lines] == [
                "figures: 1/3",
                "figures: 2/3",
                "figures: 3/3",
            ]
        assert list(_progress("abc", 3, "figures", False)) == ["a", "b", "c"]
        assert stream.getvalue() == text  # show=False: silent


def test_fit_writes_nothing_to_stdout_but_results(files, tmp_path, capsys):
    # Progress is on stderr so that the closing line can be piped.
    assert _fit(files[:2], tmp_path / "m.sysid", "--verbose") == 0
    out = capsys.readouterr().out
    assert "restart" not in out
    assert np.all(["NRMSE" in line or "fitted" in line for line in out.splitlines()])


def test_data_the_estimator_rejects_names_the_file(files, tmp_path, capsys):
    short = tmp_path / "short.csv"
    pd.read_csv(files[0]).head(8).to_csv(short, index=False)
    assert _fit([short], tmp_path / "m.sysid", "--output-lags", "10") == 1
    line = _error(capsys)
    assert "cannot fit to" in line and "short.csv" in line
    assert "outputs 'displacement'" in line and "at least" in line
    assert not (tmp_path / "m.sysid").exists()
