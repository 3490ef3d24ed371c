"""Tests of the ``sysid-nn modal`` command."""

import numpy as np
import pytest

from sysid_nn import ShearBuilding, load_model, modal_parameters
from sysid_nn.cli import main


@pytest.fixture(scope="module")
def saved(tmp_path_factory):
    """A linear model of a linear two-storey building, saved by ``fit``."""
    folder = tmp_path_factory.mktemp("modal")
    building = ShearBuilding(n_storeys=2, alpha=1.0, r0=0.16)
    rec = building.generate(
        2, n_samples=1500, dt=0.02, random_state=0, outputs="drift", as_frame=True
    )
    path = folder / "records.csv"
    rec.frame.to_csv(path, index=False)
    model = folder / "model.sysid"
    argv = ["fit", str(path), "--split-by", "realization", "--input"]
    argv += ["ground_acceleration", "--output", "drift_1", "--output", "drift_2"]
    argv += ["--hidden", "0"]
    argv += ["--n-init", "1", "--quiet", "--save", str(model)]
    assert main(argv) == 0
    return model, building.modal_properties()


def test_modal_prints_the_modes(saved, capsys):
    model, truth = saved
    capsys.readouterr()
    assert main(["modal", str(model)]) == 0
    lines = capsys.readouterr().out.splitlines()
    assert "dt = 0.02 s" in lines[0]
    assert "drift_1" in lines[1] and "drift_2" in lines[1]
    rows = [line.split() for line in lines[2:]]
    assert len(rows) == 2
    freqs = [float(r[1]) for r in rows]
    np.testing.assert_allclose(freqs, truth.frequency, rtol=1e-3)
    # The printed numbers are modal_parameters' at the saved dt.
    modes = modal_parameters(load_model(model), 0.02)
    modes = modes[modes.structural]
    np.testing.assert_allclose(freqs, modes.frequency_hz.round(4))
    assert float(rows[0][2].strip("[,")) == pytest.approx(
        modes.frequency_hz_low.iloc[0], abs=1e-4
    )


def test_modal_all_lists_numerical_modes(saved, capsys):
    model, _ = saved
    capsys.readouterr()
    assert main(["modal", str(model), "--all", "--level", "0.9"]) == 0
    out = capsys.readouterr().out
    assert "90 % interval" in out and "kind" in out.splitlines()[1]


def test_modal_wrong_dt_is_an_error(saved, capsys):
    model, _ = saved
    capsys.readouterr()
    assert main(["modal", str(model), "--dt", "0.01"]) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "fitted at dt = 0.02 s" in err[0]


def test_modal_missing_model_one_line(tmp_path, capsys):
    assert main(["modal", str(tmp_path / "none.joblib")]) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "none.joblib" in err[0]


def test_modal_of_a_distilled_ensemble_reads_its_network(saved, capsys, tmp_path):
    model, truth = saved
    records = model.parent / "records.csv"
    ensemble = tmp_path / "ensemble.sysid"
    argv = ["fit", str(records), "--split-by", "realization", "--input"]
    argv += ["ground_acceleration", "--output", "drift_1", "--output", "drift_2"]
    argv += ["--hidden", "0", "--n-init", "1", "--members", "2", "--distil"]
    assert main([*argv, "--save", str(ensemble)]) == 0
    out = capsys.readouterr().out
    assert "median of 2 × TDL (hidden_layer_sizes=(), n_init=1), one network" in out
    loaded = load_model(ensemble)
    assert f"misses the fitted records by {loaded.network_record_error_:.3g}" in out
    assert main(["modal", str(ensemble)]) == 0
    lines = capsys.readouterr().out.splitlines()
    assert "the network fitted to the median of 2 (network_)" in lines[0]
    freqs = [float(line.split()[1]) for line in lines[2:]]
    modes = modal_parameters(loaded.network_, 0.02)
    np.testing.assert_allclose(freqs, modes[modes.structural].frequency_hz.round(4))
    np.testing.assert_allclose(freqs, truth.frequency, rtol=1e-3)
    # `validate` scores the median and the network, and its report gives
    # the network's modes.
    out = tmp_path / "validation"
    argv = ["validate", "--model", str(ensemble), str(records)]
    assert main([*argv, "--split-by", "realization", "--out", str(out)]) == 0
    printed = capsys.readouterr().out
    head, network = printed.split("The network fitted to the median (network_")
    assert "NRMSE" in head and "simulation" in network
    report = (out / "report.md").read_text()
    assert "Of the network fitted to the ensemble's median (`network_`)" in report
