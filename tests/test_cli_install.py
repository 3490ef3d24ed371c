"""Installing and running the package as the README says: nothing written into
the installed package, nothing but the package in the wheel."""

import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]

RUN_KERNEL = """
from sysid_nn import HystereticOscillator
from sysid_nn._kernels import cache_dir
HystereticOscillator(r0=0.05).generate(1, n_samples=50, random_state=0)
print(cache_dir())
"""


def _installed_copy(tmp_path, folder="site-packages"):
    """The package copied alone into a fresh folder, as pip installs it."""
    site = tmp_path / folder
    shutil.copytree(
        ROOT / "sysid_nn",
        site / "sysid_nn",
        ignore=shutil.ignore_patterns("__pycache__"),
    )
    return site


def _run(site, env_extra):
    env = {k: v for k, v in os.environ.items() if not k.startswith("NUMBA_CACHE")}
    env.update(PYTHONPATH=str(site), PYTHONDONTWRITEBYTECODE="1", **env_extra)
    proc = subprocess.run(
        [sys.executable, "-c", RUN_KERNEL],
        cwd=site.parent,
        env=env,
        capture_output=True,
        text=True,
        check=False,
    )
    assert proc.returncode == 0, proc.stderr
    return Path(proc.stdout.strip().splitlines()[-1])


def _numba_files(folder):
    return sorted(p.name for p in folder.rglob("*") if p.suffix in {".nbi", ".nbc"})


def test_numba_cache_stays_out_of_the_installed_package(tmp_path):
    site = _installed_copy(tmp_path)
    cache = _run(site, {"XDG_CACHE_HOME": str(tmp_path / "user-cache")})
    # Nothing pip does not know about inside the package: no folder that could
    # outlive an uninstall and shadow the next install.
    assert _numba_files(site) == []
    assert not list(site.rglob("__pycache__"))
    assert cache.is_relative_to(tmp_path / "user-cache")
    assert any(name.endswith(".nbi") for name in _numba_files(cache))
    # A second process loads the cache instead of compiling again.
    before = {p: p.stat().st_mtime_ns for p in cache.rglob("*.nbi")}
    assert _run(site, {"XDG_CACHE_HOME": str(tmp_path / "user-cache")}) == cache
    assert {p: p.stat().st_mtime_ns for p in cache.rglob("*.nbi")} == before


def test_installs_of_the_same_sources_share_the_compiled_kernels(tmp_path):
    # A regular and an editable install live in different folders; the kernels
    # compiled by one are loaded, not compiled again, by the other.
    user_cache = {"XDG_CACHE_HOME": str(tmp_path / "user-cache")}
    cache = _run(_installed_copy(tmp_path, "site-packages"), user_cache)
    before = {p: p.stat().st_mtime_ns for p in cache.rglob("*.nb*")}
    assert before
    assert _run(_installed_copy(tmp_path, "checkout"), user_cache) == cache
    assert {p: p.stat().st_mtime_ns for p in cache.rglob("*.nb*")} == before


def test_a_changed_kernel_module_recompiles(tmp_path):
    user_cache = {"XDG_CACHE_HOME": str(tmp_path / "user-cache")}
    site = _installed_copy(tmp_path)
    cache = _run(site, user_cache)
    before = {p: p.stat().st_mtime_ns for p in cache.rglob("*.nbi")}
    # A kernel module the oscillator's kernels do not import changes.
    with open(site / "sysid_nn" / "_kernels" / "_propagation.py", "a") as f:
        f.write("\n# changed\n")
    _run(site, user_cache)
    after = {p: p.stat().st_mtime_ns for p in cache.rglob("*.nbi")}
    assert all(after[p] != before[p] for p in before)


def test_numba_cache_dir_setting_is_respected(tmp_path):
    site = _installed_copy(tmp_path)
    chosen = tmp_path / "chosen"
    _run(site, {"NUMBA_CACHE_DIR": str(chosen), "XDG_CACHE_HOME": str(tmp_path / "x")})
    assert _numba_files(site) == []
    assert _numba_files(chosen) and not (tmp_path / "x").exists()


def test_other_libraries_keep_numba_defaults():
    from numba.core import caching

    import sysid_nn._kernels as kernels

    def elsewhere():  # pragma: no cover - never called
        return 1

    # The package's locator declines functions that are not its kernels.
    locator = kernels._UserCacheLocator.from_function(elsewhere, __file__)
    assert locator is None
    impl = getattr(caching, "CacheImpl", None) or caching._CacheImpl
    assert impl._locator_classes.count(kernels._UserCacheLocator) == 1


def test_wheel_holds_only_the_package(tmp_path):
    """The include pattern must not pack sysid_nn_results/ or other folders."""
    tomllib = pytest.importorskip("tomllib")
    setuptools = pytest.importorskip("setuptools")
    config = tomllib.loads((ROOT / "pyproject.toml").read_text())
    find = config["tool"]["setuptools"]["packages"]["find"]
    for folder in (
        "sysid_nn/_kernels/__pycache__",
        "sysid_nn_results",
        "sysid_nn_records",
        "sysid_nn.egg-info",
        "docs",
    ):
        (tmp_path / folder).mkdir(parents=True)
    (tmp_path / "sysid_nn" / "__init__.py").touch()
    (tmp_path / "sysid_nn" / "_kernels" / "__init__.py").touch()
    found = setuptools.find_namespace_packages(
        where=str(tmp_path),
        include=find.get("include", ("*",)),
        exclude=find.get("exclude", ()),
    )
    assert sorted(found) == ["sysid_nn", "sysid_nn._kernels"]
    # And on the real tree: the package and its subpackages only.
    real = setuptools.find_namespace_packages(
        where=str(ROOT), include=find["include"], exclude=find.get("exclude", ())
    )
    assert "sysid_nn" in real
    assert all(p == "sysid_nn" or p.startswith("sysid_nn.") for p in real)
    assert not any("__pycache__" in p for p in real)


def test_license_is_the_declared_bsd_3_clause():
    tomllib = pytest.importorskip("tomllib")
    project = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]
    assert project["license"] == "BSD-3-Clause"
    text = (ROOT / project["license-files"][0]).read_text()
    assert text.startswith("BSD 3-Clause License")
    assert "Copyright (c) sysid_nn developers" in text
    assert "Neither the name of the copyright holder" in text


def test_first_run_compiles_once_announced_and_apart(tmp_path, monkeypatch, capsys):
    from sysid_nn import _compile

    ran = []
    monkeypatch.setattr(_compile, "_marker", lambda: str(tmp_path / "ready"))
    monkeypatch.setattr(_compile, "_steps", lambda: [lambda: ran.append(1)] * 3)
    assert _compile.prepare_kernels(show=True) > 0
    err = capsys.readouterr().err
    assert err.count("compiling the numerical kernels") == 1
    assert "compiling kernels: 3/3" in err and len(ran) == 3
    # Compiled once: the next run neither compiles nor says anything.
    assert _compile.prepare_kernels(show=True) == 0.0
    assert capsys.readouterr().err == "" and len(ran) == 3


def test_fit_compiles_before_its_timed_fit(tmp_path, monkeypatch, capsys):
    from sysid_nn import HystereticOscillator, _compile
    from sysid_nn.cli import main

    rec = HystereticOscillator(r0=0.05).generate(
        2, n_samples=300, random_state=0, as_frame=True
    )
    rec.frame.to_csv(tmp_path / "r.csv", index=False)
    order = []
    monkeypatch.setattr(_compile, "_marker", lambda: str(tmp_path / "ready"))
    monkeypatch.setattr(_compile, "_steps", lambda: [lambda: order.append("compile")])
    import sysid_nn.cli._fit as fit_command

    real_fit = fit_command._fit
    monkeypatch.setattr(
        fit_command, "_fit", lambda *a: (order.append("fit"), real_fit(*a))[1]
    )
    argv = ["fit", str(tmp_path / "r.csv"), "--input", "excitation", "--output"]
    argv += ["displacement", "--split-by", "realization", "--hidden", "0"]
    assert main([*argv, "--save", str(tmp_path / "m.sysid")]) == 0
    assert order == ["compile", "fit"]
    assert "compiling the numerical kernels" in capsys.readouterr().err
