"""The chaos check: free runs that part ways from a nudged start."""

import numpy as np
import pandas as pd
import pytest

from sysid_nn import HystereticOscillator
from sysid_nn._analysis._sensitivity import NUDGE, chaos_hint, free_run_divergence


class DrivenMap:
    """``y(t) = r y(t-1) (1 - y(t-1)) + c u(t)``: chaotic at r = 3.9."""

    def __init__(self, r):
        self.r = r

    def simulate(self, X):
        u = np.asarray(X, dtype=float)[:, 0]
        y = np.empty(len(u))
        prev = 0.3
        for t, u_t in enumerate(u):
            prev = self.r * prev * (1.0 - prev) + 1e-3 * u_t
            y[t] = prev
        return y


@pytest.fixture
def X():
    return np.random.default_rng(0).uniform(-1, 1, (2000, 1))


def test_chaotic_free_runs_part_ways_and_get_a_hint(X):
    chaotic, settled = DrivenMap(3.9), DrivenMap(2.8)
    assert free_run_divergence(chaotic, X) > 0.1  # far above PARTED
    assert free_run_divergence(settled, X) < 1e3 * NUDGE
    hint = chaos_hint(chaotic, X)
    assert hint is not None and "free-run scores" in hint.lower()
    assert chaos_hint(settled, X) is None


def test_a_diverged_run_is_no_evidence(X):
    class Diverging:
        def simulate(self, X):
            return np.full(len(X), np.nan)

    assert np.isnan(free_run_divergence(Diverging(), X))
    assert chaos_hint(Diverging(), X) is None


def test_fit_and_validate_print_the_hint(tmp_path, capsys, monkeypatch):
    from sysid_nn._analysis import _sensitivity
    from sysid_nn.cli import main

    rec = HystereticOscillator(r0=0.05).generate(
        2, n_samples=300, random_state=0, as_frame=True
    )
    rec.frame.to_csv(tmp_path / "r.csv", index=False)
    common = ["--split-by", "realization", "--quiet"]
    fit = ["fit", str(tmp_path / "r.csv"), "--input", "excitation", "--output"]
    fit += ["displacement", "--hidden", "0", *common]
    # The package's own noise-free oscillator is not chaotic: no hint.
    assert main([*fit, "--save", str(tmp_path / "m.sysid")]) == 0
    assert "depends on its start" not in capsys.readouterr().err
    monkeypatch.setattr(_sensitivity, "chaos_hint", lambda est, X: "runs part ways")
    assert main([*fit, "--save", str(tmp_path / "m2.sysid")]) == 0
    assert "sysid-nn: warning: runs part ways" in capsys.readouterr().err
    validate = [
        "validate",
        "--model",
        str(tmp_path / "m2.sysid"),
        str(tmp_path / "r.csv"),
    ]
    assert (
        main([*validate, *common, "--max-lag", "5", "--out", str(tmp_path / "v")]) == 0
    )
    assert "sysid-nn: warning: runs part ways" in capsys.readouterr().err
    assert "Warning: Runs part ways" in (tmp_path / "v" / "report.md").read_text()
    assert pd.read_csv(tmp_path / "v" / "series.csv")["record"].nunique() == 2
