"""Tests of the section-4 study (sysid_nn.study) on tiny configurations."""

import numpy as np
import pandas as pd
import pytest

from sysid_nn.study import (
    FIGURES,
    MODES,
    PAPER_MODELS,
    StudyConfig,
    evaluate,
    fit_models,
    generate_data,
    hysteresis_loops,
    model_specs,
    run_study,
    select_typical,
    summarize,
)

# Short records, few lags and iterations: every code path, a few seconds a fit.
TINY = {
    "n_samples": 600,
    "n_test": 3,
    "n_candidates": 3,
    "max_lag": 10,
    "estimator_params": {
        "all": {"max_iter": 4, "n_init": 2, "n_iter_no_change": 4},
        "tdl": {"shooting_segments": (20,)},
        "issm": {"shooting_segments": (20,)},
    },
}
RESULT_COLUMNS = [
    "realization",
    "model",
    "output",
    "mode",
    "dt",
    "nrmse",
    "fit_percent",
    "mean",
    "std",
    "divergent",
    "whiteness_p",
    "whiteness_passed",
    "cross_positive_p",
    "cross_positive_passed",
    "cross_negative_p",
    "cross_negative_passed",
]


def _tiny(**changes):
    return StudyConfig(**{**TINY, **changes})


def _pipeline(config):
    data = generate_data(config)
    models = fit_models(data, config)
    evaluation = evaluate(models, data, config)
    return evaluation.results, summarize(evaluation, models)


@pytest.fixture(scope="module")
def study(tmp_path_factory):
    out = tmp_path_factory.mktemp("study") / "results"
    return run_study(_tiny(seed=7), out)


def test_run_study_writes_every_figure_and_table(study):
    out = study.out_dir
    names = {p.name for p in out.iterdir()}
    assert names == {*FIGURES, "results.csv", "summary.csv", "report.md"}
    for name in FIGURES:
        png = (out / name).read_bytes()
        assert png.startswith(b"\x89PNG") and len(png) > 10_000, name
    results = pd.read_csv(out / "results.csv")
    assert list(results.columns) == RESULT_COLUMNS
    assert len(results) == 3 * len(PAPER_MODELS) * len(MODES)
    assert set(results["model"]) == set(PAPER_MODELS)
    # The paper's TDL sees every third sample.
    dt = results.groupby("model")["dt"].first()
    assert dt["tdl_paper"] == pytest.approx(0.03) and dt["tdl"] == pytest.approx(0.01)
    summary = pd.read_csv(out / "summary.csv")
    assert {"mu_Ns", "sigma_Ns", "nrmse_median", "whiteness_pass_rate"} <= set(
        summary.columns
    )
    assert len(summary) == len(PAPER_MODELS) * len(MODES)
    assert not any(p.name.startswith(".") for p in out.parent.iterdir())


def test_report_sections_and_setup(study):
    report = (study.out_dir / "report.md").read_text()
    for heading in (
        "## Results at a glance",
        "## Setup",
        "### Models",
        "## One-step prediction (section 4.3)",
        "## Free-run simulation (section 4.4)",
        "## Hysteresis",
        "## Files",
    ):
        assert heading in report
    for fragment in ("seed=7", "numpy", "logical CPUs", "nearest the median peak"):
        assert fragment in report
    for name in FIGURES:
        assert f"({name})" in report
    for label in ("TDL (paper)", "ISSM (paper)", "linear (OE)", "ISSM (default)"):
        assert f"| {label} |" in report


def test_report_names_the_blas_kernels_its_figures_ran_on(study):
    # Figures are reproduced only under the same BLAS kernel: the report's
    # machine line names the ones this process runs.
    import scipy.linalg  # noqa: F401  (scipy's own BLAS)
    from threadpoolctl import threadpool_info

    report = (study.out_dir / "report.md").read_text()
    machine = next(line for line in report.splitlines() if "Machine:" in line)
    kinds = [
        f"{info['internal_api']} {info.get('architecture', '?')}"
        for info in threadpool_info()
        if info.get("user_api") == "blas"
    ]
    assert kinds
    assert all(kind in machine for kind in kinds)


def test_summary_reuses_eq_19_20_statistics(study):
    ev, summary = study.evaluation, study.summary
    row = summary.query("model == 'issm' and mode == 'simulation'").iloc[0]
    stats = ev.statistics["simulation"]["displacement"]["ISSM (default)"]
    assert row["mu_Ns"] == stats.mu and row["sigma_Ns"] == stats.sigma
    per = ev.results.query("model == 'issm' and mode == 'simulation'")
    np.testing.assert_allclose(per["mean"].mean(), stats.mu)
    np.testing.assert_allclose(np.sqrt((per["std"] ** 2).mean()), stats.sigma)


def test_training_record_has_typical_amplitude(study):
    data = study.data
    peaks = data.candidate_peaks
    chosen = peaks[data.train_index[0]]
    assert np.all(np.abs(peaks - np.median(peaks)) >= abs(chosen - np.median(peaks)))
    np.testing.assert_array_equal(np.max(np.abs(data.train.displacement[0])), chosen)


def test_same_seed_serial_and_parallel_identical(study):
    serial = _pipeline(_tiny(seed=7))
    parallel = _pipeline(_tiny(seed=7, n_jobs=2))
    for got in (serial, parallel):
        pd.testing.assert_frame_equal(got[0], study.results, check_exact=True)
        pd.testing.assert_frame_equal(got[1], study.summary, check_exact=True)
    other = _pipeline(_tiny(seed=8, models=("linear",)))[0]
    assert not np.array_equal(
        other["nrmse"], study.results.query("model == 'linear'")["nrmse"]
    )


def test_dask_cluster_gives_identical_results(tmp_path):
    distributed = pytest.importorskip("dask.distributed")
    config = _tiny(seed=7, models=("linear", "issm"), n_jobs=2)
    with distributed.LocalCluster(
        n_workers=2, threads_per_worker=1, processes=False, dashboard_address=None
    ) as cluster:
        on_dask = run_study(config, tmp_path / "d", scheduler=cluster.scheduler_address)
    serial = _pipeline(_tiny(seed=7, models=("linear", "issm")))
    pd.testing.assert_frame_equal(on_dask.results, serial[0], check_exact=True)
    pd.testing.assert_frame_equal(on_dask.summary, serial[1], check_exact=True)


def test_existing_output_is_kept_unless_overwrite(tmp_path):
    out = tmp_path / "out"
    out.mkdir()
    (out / "keep.txt").write_text("x")
    with pytest.raises(FileExistsError, match="overwrite=True"):
        run_study(_tiny(), out)
    assert (out / "keep.txt").exists()


def test_failed_run_leaves_nothing(tmp_path, monkeypatch):
    import sysid_nn.study._run as study_module

    def boom(*args, **kwargs):
        raise RuntimeError("interrupted")

    monkeypatch.setattr(study_module, "fit_models", boom)
    with pytest.raises(RuntimeError, match="interrupted"):
        run_study(_tiny(), tmp_path / "out")
    assert list(tmp_path.iterdir()) == []


def test_overwrite_replaces_directory(tmp_path):
    out = tmp_path / "out"
    out.mkdir()
    (out / "stale.txt").write_text("x")
    config = _tiny(models=("linear",), n_test=1)
    run_study(config, out, overwrite=True)
    assert not (out / "stale.txt").exists()
    assert (out / "report.md").exists()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out"]


def test_model_specs_paper_settings_and_overrides():
    specs = model_specs(StudyConfig(seed=3, n_jobs=2))
    tdl = specs["tdl_paper"]
    assert tdl.step == 3 and tdl.outputs == ("displacement",)
    params = tdl.estimator.get_params()
    assert (params["output_lags"], params["input_lags"]) == (6, 5)
    assert params["hidden_layer_sizes"] == (9,) and params["activation"] == "logistic"
    assert params["focus"] == "prediction" and params["n_jobs"] == 2
    issm = specs["issm_paper"]
    assert issm.outputs == ("displacement", "velocity")
    assert issm.estimator.get_params()["n_states"] == 3
    assert specs["linear"].estimator.get_params()["hidden_layer_sizes"] == ()
    quick = model_specs(
        StudyConfig(quick=True, estimator_params={"tdl": {"max_iter": 2}})
    )
    assert quick["tdl"].estimator.get_params()["max_iter"] == 2
    assert quick["issm"].estimator.get_params()["n_init"] == 1


@pytest.mark.parametrize(
    ("changes", "fragment"),
    [
        ({"n_test": 0}, "n_test must be >= 1"),
        ({"n_train": 0}, "n_train must be >= 1"),
        ({"n_val": 0}, "n_val"),
        ({"seed": -1}, "seed"),
        ({"seed": 2**32}, "seed must be < 2**32"),
        ({"n_jobs": 0}, "n_jobs"),
        ({"models": ("tdl", "nope")}, "models"),
        ({"models": ()}, "models"),
        ({"n_candidates": 1, "n_train": 2}, "n_candidates"),
        ({"n_samples": 50}, "n_samples"),
        ({"alpha": 1.5}, "alpha"),
        ({"estimator_params": {"tdll": {}}}, "estimator_params"),
        ({"n_test": 2.5}, "n_test must be an integer"),
    ],
)
def test_config_rejects_bad_values(changes, fragment):
    with pytest.raises(ValueError, match=fragment.replace("*", r"\*")):
        StudyConfig(**changes)


def test_select_typical():
    assert select_typical([5.0, 1.0, 3.0, 2.0, 4.0], 1).tolist() == [2]
    assert select_typical([5.0, 1.0, 3.0, 2.0, 4.0], 3).tolist() == [2, 3, 4]
    with pytest.raises(ValueError, match="exceeds"):
        select_typical([1.0], 2)


def test_hysteretic_element_reproduces_true_state_from_displacement(study):
    test = study.data.test
    z = study.data.oscillator.hysteretic_state(test.displacement[0])
    scale = np.max(np.abs(test.hysteretic[0]))
    assert np.max(np.abs(z - test.hysteretic[0])) < 1e-2 * scale
    loops = hysteresis_loops(study.models, study.data, study.evaluation)
    labels = {m.label for m in study.models.values()}
    assert set(loops.force) <= labels
    assert set(loops.state) <= {"ISSM (paper)", "ISSM (default)"}
    assert loops.state and set(loops.state_correlation) == set(loops.state)
    steps = {m.label: m.step for m in study.models.values()}
    z_true = test.hysteretic[0]
    for label, (_, z_m) in loops.state.items():
        # Against the true hysteretic state, which no fitted state matches.
        expected = abs(np.corrcoef(z_m, z_true[:: steps[label]])[0, 1])
        r = loops.state_correlation[label]
        assert r == pytest.approx(expected, rel=1e-12), label
        assert 0 < r < 1 - 1e-6, label


def test_report_states_the_verdicts_of_its_results(study):
    report = (study.out_dir / "report.md").read_text()
    by = study.summary.set_index(["model", "mode"])
    paper = [
        by.loc[(m, "simulation"), "nrmse_median"] for m in ("tdl_paper", "issm_paper")
    ]
    for value in paper:
        assert f"{value:.4g}" in report
    simulates = "The paper's networks as published do not simulate unseen"
    assert (simulates in report) == all(v > 1 for v in paper)
    rates = by.xs("prediction", level="mode")["whiteness_pass_rate"]
    none_white = "No model's one-step residuals pass the whiteness test**"
    assert (none_white in report) == (rates.max() == 0)
    assert "docs/user_guide/pitfalls.rst" in report


def test_verdicts_follow_the_numbers(study):
    from sysid_nn.study._report import _verdicts

    summary = study.summary.copy()
    sim = summary["mode"] == "simulation"
    summary.loc[sim, "nrmse_median"] = 2.0
    summary["whiteness_pass_rate"] = 0.0
    text = " ".join(_verdicts(summary))
    assert "do not simulate unseen realisations" in text
    assert "No model's one-step residuals pass the whiteness test**" in text
    assert "unlike the paper's figs 4.3-4.4" in text and "pitfalls.rst" in text
    summary.loc[sim, "nrmse_median"] = 0.5
    summary["whiteness_pass_rate"] = 1.0
    text = " ".join(_verdicts(summary))
    assert "networks as published simulate unseen realisations" in text
    assert "unlike the paper" not in text and "100 %" in text
    assert "Every model's one-step residuals pass" in text
    summary.loc[summary["model"] == "linear", "whiteness_pass_rate"] = 0.0
    assert "Some models' one-step residuals pass" in " ".join(_verdicts(summary))
    # Without the paper's networks there is no comparison with the paper.
    summary["whiteness_pass_rate"] = 1.0
    text = " ".join(_verdicts(summary.query("model == 'linear'")))
    assert "paper" not in text and "linear (OE) 100 %" in text
    # One model is one model, not "some models".
    assert "The model's one-step residuals pass the whiteness test" in text


def _study_figures(study, *names):
    from sysid_nn.study._figures import _figures

    loops = hysteresis_loops(study.models, study.data, study.evaluation)
    builders = _figures(study.models, study.data, study.evaluation, loops)
    return [builders[name]() for name in names]


def test_correlation_panels_share_a_lag_range_of_a_natural_period(study):
    acf, ccf = _study_figures(
        study,
        "fig4_3_residual_autocorrelation.png",
        "fig4_4_residual_cross_correlation.png",
    )
    period = study.data.natural_period
    limits = {ax.get_xlim() for ax in acf.axes}
    assert len(limits) == 1 and limits.pop()[1] >= period
    for ax in acf.axes:
        assert ax.get_lines()[0].get_xdata()[-1] >= period
    assert len({ax.get_xlim() for ax in ccf.axes}) == 1
    for ax in ccf.axes:
        assert ax.get_lines()[0].get_xdata()[0] <= -period
        legend = [t.get_text() for t in ax.get_legend().get_texts()]
        assert legend[0] == "excitation F [m/s²]"
        assert ax.get_xlabel().startswith("lag τ [s]")


def test_figures_carry_units_and_one_model_per_loop(study):
    training, response, stats, loops = _study_figures(
        study,
        "fig4_1_training_data.png",
        "fig4_2_prediction.png",
        "fig4_7_simulation_error_statistics.png",
        "hysteresis.png",
    )
    assert [ax.get_ylabel() for ax in training.axes] == [
        "excitation F [m/s²]",
        "displacement X [m]",
    ]
    assert {ax.get_xlabel() for ax in training.axes} == {"time t [s]"}
    assert {ax.get_ylabel() for ax in response.axes} == {"displacement X [m]"}
    assert {ax.get_xlabel() for ax in response.axes} == {"time t [s]"}
    assert stats.axes[0].get_ylabel().startswith("error [m]")
    shown = [ax for ax in loops.axes if ax.get_visible()]
    data = hysteresis_loops(study.models, study.data, study.evaluation)
    # Only models with a hidden state: no Bouc-Wen loops drawn for the others.
    assert data.state and len(shown) == len(data.state)
    titles = " ".join(ax.get_title() for ax in shown)
    assert "TDL" not in titles and "linear" not in titles
    for ax in shown:
        assert len(ax.get_legend().get_texts()) == 2  # the truth and one model
        assert ax.get_xlabel() == "displacement X [m]"
        assert ax.get_ylabel().endswith("[m]")


def test_long_records_get_an_error_trace_and_a_zoom():
    import matplotlib.pyplot as plt

    from sysid_nn.study._figures import LONG_RECORD, show_long_record

    t = np.arange(3 * LONG_RECORD) * 0.01
    measured = np.sin(t)
    model = measured + 0.01 * np.cos(7 * t)
    model[2000] += 0.5  # the largest error, where the zoom must look
    _, ax = plt.subplots()
    ax.plot(t, measured)
    inset = show_long_record(ax, t, measured, model, std=np.full(t.size, 0.02))
    labels = [line.get_label() for line in ax.get_lines()]
    assert "error (measured - model)" in labels
    error = ax.get_lines()[-1].get_ydata()
    np.testing.assert_allclose(error, measured - model)
    lo, hi = inset.get_lines()[0].get_xdata()[[0, -1]]
    assert lo <= t[2000] <= hi and hi - lo < 0.1 * t[-1]
    assert inset.collections  # the band, visible at the zoom's scale
    plt.close(ax.figure)


def test_a_study_without_hidden_states_draws_no_hysteresis(study):
    from sysid_nn.study._figures import _figures

    linear = {k: m for k, m in study.models.items() if k == "linear"}
    loops = hysteresis_loops(linear, study.data, study.evaluation)
    assert not loops.state
    assert "hysteresis.png" not in _figures(linear, study.data, study.evaluation, loops)


def test_pickles_name_the_public_module():
    import pickle

    from sysid_nn.study import StudyModel

    model = StudyModel("linear", None, ("excitation",), ("displacement",))
    for obj in (StudyConfig(seed=1), model):
        dumped = pickle.dumps(obj)
        assert b"sysid_nn.study" in dumped and b"sysid_nn.study._" not in dumped
        assert pickle.loads(dumped) == obj


def test_report_does_not_claim_noise_in_noise_free_records(study):
    report = (study.out_dir / "report.md").read_text()
    assert "carry white noise" not in report
    misfit = [
        w for ws in study.data.fit_warnings.values() for w in ws if "white misfit" in w
    ]
    # A white misfit on the study's records is explained for what it is.
    assert bool(misfit) == ("carry no measurement noise" in report)


def test_a_report_on_user_records_speaks_plainly(tmp_path):
    """No paper's notation or figure numbers, in the files or the figures."""
    import matplotlib.pyplot as plt

    from sysid_nn import HystereticOscillator, TDLRegressor
    from sysid_nn.study import StudyModel, run_validation
    from sysid_nn.study._figures import _figures

    rec = HystereticOscillator(r0=0.05).generate(2, n_samples=300, random_state=0)
    records = {"force": list(rec.excitation), "x": list(rec.displacement)}
    model = StudyModel(
        "ARX", TDLRegressor(hidden_layer_sizes=(), n_init=1), ("force",), ("x",)
    )
    model.estimator.fit(*model.arrays(records))
    out = tmp_path / "validation"
    result = run_validation(model, records, out, dt=0.01, max_lag=10, series=None)
    names = sorted(p.name for p in out.glob("*.png"))
    assert "simulation_error_statistics.png" in names
    assert not [n for n in names if n.startswith("fig")]
    data = {"test": records, "dt": 0.01, "paper_terms": False}
    for plain in (True, False):
        data["paper_terms"] = not plain
        build = _figures({"ARX": model}, data, result.evaluation, None)
        fig = build["fig4_7_simulation_error_statistics.png"]()
        ax = fig.axes[0]
        texts = [ax.get_title(), *(t.get_text() for t in ax.get_legend().texts)]
        plt.close(fig)
        shown = " ".join(texts)
        assert ("μ_Ns" in shown) != plain and ("fig. 4.7" in shown) != plain
        if plain:
            assert "Mean error and error std of simulation errors" in texts[0]
            assert texts[1:] == ["mean error", "error std"]


def test_figure_titles_fit_their_figures(tmp_path, monkeypatch):
    """A long model label and the correlation figures' notes are not clipped."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    from sysid_nn import HystereticOscillator, TDLRegressor
    from sysid_nn.study import StudyModel, run_validation

    rec = HystereticOscillator(r0=0.05).generate(2, n_samples=300, random_state=0)
    records = {"force": list(rec.excitation), "x": list(rec.displacement)}
    label = "TDL (" + ", ".join(f"option_{k}={k}" for k in range(12)) + ")"
    est = TDLRegressor(hidden_layer_sizes=(), n_init=1)
    model = StudyModel(label, est, ("force",), ("x",))
    est.fit(*model.arrays(records))
    overflow = {}
    savefig = Figure.savefig

    def measuring(fig, fname, *args, **kwargs):
        result = savefig(fig, fname, *args, **kwargs)
        renderer = FigureCanvasAgg(fig).get_renderer()
        fig.draw(renderer)
        titles = [fig._suptitle] if fig._suptitle else []
        titles += [ax.title for ax in fig.axes if ax.title.get_text()]
        box = fig.bbox
        overflow[str(fname)] = [
            t.get_text()
            for t in titles
            if t.get_window_extent(renderer).x0 < box.x0 - 1
            or t.get_window_extent(renderer).x1 > box.x1 + 1
        ]
        return result

    monkeypatch.setattr(Figure, "savefig", measuring)
    run_validation(model, records, tmp_path / "v", dt=0.01, max_lag=10, series=None)
    assert len(overflow) == 6
    assert all(not clipped for clipped in overflow.values()), {
        k.rsplit("/", 1)[1]: v for k, v in overflow.items() if v
    }
