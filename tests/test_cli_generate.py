"""Tests of the ``sysid-nn generate`` command."""

import subprocess
import sys

import pandas as pd
import pytest

from sysid_nn import HystereticOscillator
from sysid_nn.cli import main

COLUMNS = ["realization", "t", "excitation", "displacement", "velocity", "hysteretic"]
SMALL = ["--n-realizations", "2", "--n-samples", "300", "--seed", "3"]


def _expected(r0=0.05):
    osc = HystereticOscillator(r0=r0)
    return osc.generate(2, n_samples=300, random_state=3, as_frame=True).frame


def test_generate_csv(tmp_path, capsys):
    out = tmp_path / "records.csv"
    assert main(["generate", *SMALL, "--r0", "0.05", "--out", str(out)]) == 0
    frame = pd.read_csv(out)
    assert list(frame.columns) == COLUMNS
    assert len(frame) == 600
    pd.testing.assert_frame_equal(frame, _expected(), check_exact=False, rtol=1e-12)
    printed = capsys.readouterr().out
    assert "wrote 2 realisation(s) x 300 samples" in printed
    assert str(out) in printed


def test_generate_parquet_and_default_calibration(tmp_path, capsys):
    pytest.importorskip("pyarrow")
    out = tmp_path / "records.parquet"
    assert main(["generate", *SMALL, "--out", str(out)]) == 0
    r0 = HystereticOscillator().calibrate_r0()
    pd.testing.assert_frame_equal(pd.read_parquet(out), _expected(r0))
    assert f"r0={r0:.6g}" in capsys.readouterr().out


@pytest.mark.parametrize(
    ("args", "fragment"),
    [
        (["--n-realizations", "0"], "--n-realizations"),
        (["--n-samples", "-3"], "--n-samples"),
        (["--dt", "0"], "--dt"),
        (["--dt", "abc"], "--dt"),
        (["--r0", "-1"], "--r0"),
        (["--seed", "x"], "--seed"),
        (["--seed", "-1"], "--seed"),
    ],
)
def test_bad_arguments_exit_2(tmp_path, capsys, args, fragment):
    with pytest.raises(SystemExit) as exc:
        main(["generate", *args, "--out", str(tmp_path / "r.csv")])
    assert exc.value.code == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err[-1].startswith("sysid-nn generate: error:")
    assert fragment in err[-1]
    assert not (tmp_path / "r.csv").exists()


def test_bad_suffix_and_missing_arguments_exit_2(tmp_path, capsys):
    with pytest.raises(SystemExit) as exc:
        main(["generate", "--out", str(tmp_path / "r.txt")])
    assert exc.value.code == 2
    assert ".csv or .parquet" in capsys.readouterr().err
    for argv in (["generate"], [], ["no-such-command"]):
        with pytest.raises(SystemExit) as exc:
            main(argv)
        assert exc.value.code == 2


@pytest.mark.parametrize("target", ["missing_dir/r.csv", "a_directory.csv"])
def test_unwritable_output_exits_1_with_one_line(tmp_path, capsys, target):
    (tmp_path / "a_directory.csv").mkdir()
    status = main(["generate", *SMALL, "--r0", "0.05", "--out", str(tmp_path / target)])
    assert status == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1
    assert err[0].startswith("sysid-nn: error: cannot write")
    assert "Traceback" not in err[0]


def test_python_dash_m_entry_point(tmp_path):
    out = tmp_path / "r.csv"
    proc = subprocess.run(
        [sys.executable, "-m", "sysid_nn", "generate", *SMALL, "--out", str(out)],
        capture_output=True,
        text=True,
        check=False,
    )
    assert proc.returncode == 0, proc.stderr
    assert len(pd.read_csv(out)) == 600
