"""Model files: round trips, the format's checks, and pickles refused unread."""

import copy
import json
import pathlib
import pickle
import zipfile

import joblib
import numpy as np
import pytest

from sysid_nn import load_model, save_model
from sysid_nn.cli import main

KINDS = [(kind, p) for kind in ("linear", "tdl", "issm") for p in (1, 2)]


class _Marker:
    """Unpickling this creates ``path``: the code a crafted file would run."""

    def __init__(self, path):
        self.path = pathlib.Path(path)

    def __reduce__(self):
        return pathlib.Path.touch, (self.path,)


def _assert_same(a, b):
    assert type(a) is type(b)
    if isinstance(a, tuple):
        for x, y in zip(a, b, strict=True):
            _assert_same(x, y)
    else:
        np.testing.assert_array_equal(a, b, strict=True)


@pytest.mark.parametrize("kind", KINDS, ids=lambda k: f"{k[0]}-{k[1]}")
def test_round_trip_is_bit_identical(fitted_models, tmp_path, kind):
    est, X, y = fitted_models[kind]
    path = tmp_path / "model.sysid"
    save_model(est, path)
    loaded = load_model(path)
    assert type(loaded) is type(est)
    assert loaded.get_params() == est.get_params()
    assert set(loaded.__dict__) == set(est.__dict__)
    _assert_same(loaded.simulate(X), est.simulate(X))
    _assert_same(loaded.simulate(X, return_std=True), est.simulate(X, return_std=True))
    _assert_same(loaded.predict(X, y), est.predict(X, y))
    _assert_same(
        loaded.predict(X, y, return_std=True), est.predict(X, y, return_std=True)
    )
    # A run started from measured outputs (the initial-state fit).
    late = {"X": X[50:], "y_init": y[50:80]}
    _assert_same(loaded.simulate(**late), est.simulate(**late))
    # Every attribute comes back with its type (numpy scalars, Bunches,
    # dataclasses, tuples), not merely equal values.
    for name, value in est.__dict__.items():
        assert type(loaded.__dict__[name]) is type(value), name
    assert loaded.rest_check_.keys() == est.rest_check_.keys()
    np.testing.assert_array_equal(
        loaded._diagnosis.noise_variance, est._diagnosis.noise_variance
    )
    assert loaded.training_history_ == est.training_history_


def test_an_issm_started_from_a_tdl_round_trips(tmp_path):
    """Its fitted attributes hold the TDL it started from (``tdl_``)."""
    import warnings

    from sysid_nn import ISSMRegressor, TDLRegressor

    rng = np.random.default_rng(2)
    X = rng.standard_normal((300, 1))
    y = np.convolve(np.tanh(X[:, 0]), [0.0, 0.6, 0.3])[:300]
    est = ISSMRegressor(init="tdl", hidden_layer_sizes=(3,), n_init=1, max_iter=3)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        est.fit(X, y)
    save_model(est, tmp_path / "m.sysid")
    loaded = load_model(tmp_path / "m.sysid")
    assert type(loaded.tdl_) is TDLRegressor
    np.testing.assert_array_equal(loaded.tdl_.simulate(X), est.tdl_.simulate(X))
    np.testing.assert_array_equal(loaded.simulate(X), est.simulate(X))


def test_the_file_is_data_only(fitted_models, tmp_path):
    est, _, _ = fitted_models["issm", 2]
    path = tmp_path / "model.sysid"
    save_model(est, path, inputs=["u1", "u2"], outputs=["y1", "y2"], dt=0.01)
    with zipfile.ZipFile(path) as archive:
        names = archive.namelist()
        header = json.loads(archive.read("model.json"))
        for name in names[1:]:
            # Arrays read without pickle support: no object arrays inside.
            with archive.open(name) as f:
                np.lib.format.read_array(f, allow_pickle=False)
    assert names[0] == "model.json"
    assert all(n.startswith("arrays/") and n.endswith(".npy") for n in names[1:])
    assert header["format_version"] == 1
    assert header["estimator"]["name"] == "ISSMRegressor"
    _, info = load_model(path, with_info=True)
    assert info.inputs == ("u1", "u2") and info.outputs == ("y1", "y2")
    assert info.dt == 0.01 and info.files == [] and info.units == {}


def _rewrite_header(path, change):
    with zipfile.ZipFile(path) as archive:
        entries = {n: archive.read(n) for n in archive.namelist()}
    header = json.loads(entries["model.json"])
    change(header)
    entries["model.json"] = json.dumps(header).encode()
    with zipfile.ZipFile(path, "w") as archive:
        for name, data in entries.items():
            archive.writestr(name, data)


def test_newer_format_and_unknown_types_are_refused(fitted_models, tmp_path):
    est, _, _ = fitted_models["tdl", 1]
    path = tmp_path / "model.sysid"
    save_model(est, path)
    _rewrite_header(path, lambda h: h.update(format_version=2))
    with pytest.raises(ValueError, match=r"format version 2.*reads versions up to 1"):
        load_model(path)
    save_model(est, path)
    # A type outside the whitelist is refused, not looked up.
    _rewrite_header(
        path,
        lambda h: h["estimator"]["v"].update(extra={"t": "dataclass", "name": "Path"}),
    )
    with pytest.raises(ValueError, match="unknown type 'dataclass'"):
        load_model(path)
    save_model(est, path)
    _rewrite_header(path, lambda h: h["estimator"].update(name="os.system"))
    with pytest.raises(ValueError, match="unknown type 'estimator'"):
        load_model(path)
    save_model(est, path)
    _rewrite_header(path, lambda h: h.update(estimator={"t": "bunch", "v": {}}))
    with pytest.raises(ValueError, match="no estimator"):
        load_model(path)
    save_model(est, path)
    _rewrite_header(path, lambda h: h["info"].update(inputs=[1, 2]))
    with pytest.raises(ValueError, match=r"damaged or not a model file \(info\)"):
        load_model(path)


def test_save_model_checks_its_arguments(fitted_models, tmp_path):
    from sklearn.exceptions import NotFittedError
    from sklearn.linear_model import Ridge

    from sysid_nn import TDLRegressor

    est, _, _ = fitted_models["tdl", 2]
    with pytest.raises(ValueError, match="inputs must be 2 column name"):
        save_model(est, tmp_path / "m.sysid", inputs=["u"])
    with pytest.raises(ValueError, match="dt must be a finite number > 0"):
        save_model(est, tmp_path / "m.sysid", dt=-1.0)
    with pytest.raises(TypeError, match="an ISSMRegressor or an EnsembleRegressor"):
        save_model(Ridge(), tmp_path / "m.sysid")
    with pytest.raises(NotFittedError):
        save_model(TDLRegressor(), tmp_path / "m.sysid")
    est.__dict__["odd_"] = {1: "non-string key"}
    try:
        with pytest.raises(TypeError, match=r"odd_.*cannot hold"):
            save_model(est, tmp_path / "m.sysid")
    finally:
        del est.__dict__["odd_"]


@pytest.mark.parametrize("compress", [0, 3, ("gzip", 3), ("xz", 3)])
def test_a_crafted_pickle_is_refused_unread(tmp_path, compress):
    marker = tmp_path / "ran"
    # The crafted object does run code when unpickled...
    pickle.loads(pickle.dumps(_Marker(tmp_path / "control")))
    assert (tmp_path / "control").exists()
    # ...but load_model refuses the file before unpickling anything.
    crafted = tmp_path / "model.joblib"
    joblib.dump(_Marker(marker), crafted, compress=compress)
    with pytest.raises(ValueError, match=r"is a pickle.*trusted=True"):
        load_model(crafted)
    assert not marker.exists()


def test_validate_refuses_a_crafted_pickle(tmp_path, capsys):
    marker = tmp_path / "ran"
    crafted = tmp_path / "model.joblib"
    with open(crafted, "wb") as f:
        pickle.dump(_Marker(marker), f)
    data = tmp_path / "data.csv"
    data.write_text("t,u,y\n0,1,2\n0.1,2,3\n")
    argv = [
        "validate",
        "--model",
        str(crafted),
        str(data),
        "--out",
        str(tmp_path / "v"),
    ]
    assert main(argv) == 1
    err = capsys.readouterr().err
    assert "is a pickle" in err and "--trust-pickle" in err
    assert not marker.exists() and not (tmp_path / "v").exists()


def test_trusted_pickles_still_load_with_a_warning(fitted_models, tmp_path):
    from sklearn.utils import Bunch

    from sysid_nn.study import StudyModel

    est, X, _ = fitted_models["linear", 1]
    bare = tmp_path / "bare.joblib"
    joblib.dump(est, bare)
    with pytest.warns(UserWarning, match="is a pickle; loading it ran any code"):
        loaded = load_model(bare, trusted=True)
    np.testing.assert_array_equal(loaded.simulate(X), est.simulate(X))
    # The bundle earlier versions of `sysid-nn fit --save` wrote.
    bundle = Bunch(
        model=StudyModel("TDL", est, ("u1", "u2"), ("y",)),
        dt=0.5,
        units={"y": "m"},
        files=["a.csv"],
        split_by=None,
        sysid_nn_version="0.1.0.dev0",
    )
    old = tmp_path / "old.joblib"
    joblib.dump(bundle, old)
    with pytest.warns(UserWarning, match="is a pickle"):
        _, info = load_model(old, trusted=True, with_info=True)
    assert info.inputs == ("u1", "u2") and info.dt == 0.5 and info.files == ["a.csv"]


def test_other_files_are_not_models(tmp_path):
    text = tmp_path / "data.csv"
    text.write_text("x^,y\n1,2\n")  # starts like zlib's magic, but is text
    with pytest.raises(ValueError, match="not a model file"):
        load_model(text, trusted=True)
    archive = tmp_path / "other.zip"
    with zipfile.ZipFile(archive, "w") as z:
        z.writestr("a.txt", "hello")
    with pytest.raises(ValueError, match="zip archive but not a model file"):
        load_model(archive)


def test_a_model_of_another_version_warns_on_load(fitted_models, tmp_path):
    import warnings

    from sysid_nn import InconsistentVersionWarning

    est, _, _ = fitted_models["linear", 1]
    path = tmp_path / "model.sysid"
    save_model(est, path)
    with warnings.catch_warnings():
        warnings.simplefilter("error", InconsistentVersionWarning)
        load_model(path)
    _rewrite_header(path, lambda h: h.update(sysid_nn_version="0.0.1"))
    with pytest.warns(InconsistentVersionWarning, match="model.sysid was saved"):
        _, info = load_model(path, with_info=True)
    assert info.sysid_nn_version == "0.0.1"


def test_a_file_written_before_a_parameter_existed_loads_with_its_default(
    fitted_models, tmp_path
):
    est, X, _ = fitted_models["tdl", 1]
    older = copy.copy(est)
    del older.refit  # as a file written before the parameter existed
    path = tmp_path / "model.sysid"
    save_model(older, path)
    loaded = load_model(path)
    assert loaded.refit is False
    assert loaded.get_params() == est.get_params()
    np.testing.assert_array_equal(loaded.simulate(X), est.simulate(X))


def test_validate_reads_an_old_model_file_only_when_trusted(
    fitted_models, tmp_path, capsys
):
    import pandas as pd
    from sklearn.utils import Bunch

    from sysid_nn.study import StudyModel

    est, X, y = fitted_models["linear", 1]
    old = tmp_path / "model.joblib"
    bundle = Bunch(
        model=StudyModel("TDL", est, ("u1", "u2"), ("y",)),
        dt=0.01,
        units={},
        files=["train.csv"],
        split_by=None,
        sysid_nn_version="0.1.0.dev0",
    )
    joblib.dump(bundle, old)
    data = tmp_path / "data.csv"
    frame = pd.DataFrame({"u1": X[:, 0], "u2": X[:, 1], "y": y})
    frame.to_csv(data, index=False)
    argv = ["validate", "--model", str(old), str(data), "--dt", "0.01"]
    argv += ["--max-lag", "10", "--quiet", "--out"]
    assert main([*argv, str(tmp_path / "refused")]) == 1
    assert "--trust-pickle" in capsys.readouterr().err
    assert main([*argv, str(tmp_path / "v"), "--trust-pickle"]) == 0
    err = capsys.readouterr().err
    assert "sysid-nn: warning:" in err and "is a pickle; loading it ran" in err
    results = pd.read_csv(tmp_path / "v" / "results.csv")
    assert set(results["mode"]) == {"prediction", "simulation"}
