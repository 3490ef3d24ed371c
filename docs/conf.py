"""Sphinx configuration for the sysid_nn documentation.

The build is meant to be warning-free (``sphinx-build -W --keep-going``) on a
machine without network access:

* intersphinx inventories are used only when they are available locally (in
  ``docs/_intersphinx/<name>.inv``, see ``docs/fetch_inventories.py``) or when
  ``SYSID_NN_DOCS_INTERSPHINX=1`` explicitly allows fetching them;
* the theme fetches nothing at build time (no version switcher, no analytics);
* sphinx-gallery runs every ``examples/plot_*.py`` locally, with no binder,
  JupyterLite or remote reference links.

The API reference is generated from ``__all__`` of the public modules: every
public name is documented without editing these sources. A public module whose
file does not exist yet is left out of the reference; a module whose file
exists must import, otherwise the build fails.
"""

from __future__ import annotations

import importlib
import os
import sys
import warnings
from datetime import date
from pathlib import Path

os.environ.setdefault("MPLBACKEND", "Agg")

import matplotlib

matplotlib.use("Agg")

DOCS_DIR = Path(__file__).resolve().parent
ROOT_DIR = DOCS_DIR.parent
GENERATED_DIR = DOCS_DIR / "generated"
INVENTORY_DIR = DOCS_DIR / "_intersphinx"

# The package is normally installed (``pip install -e ".[docs]"``); fall back to
# the source tree so that the documentation also builds from a bare checkout.
if str(ROOT_DIR) not in sys.path:
    sys.path.insert(0, str(ROOT_DIR))
# Helpers of this configuration (the gallery's sort key) live beside it.
if str(DOCS_DIR) not in sys.path:
    sys.path.insert(0, str(DOCS_DIR))

import sysid_nn

# -- Project information -----------------------------------------------------

project = "sysid_nn"
author = "sysid_nn developers"
copyright = f"{date.today().year}, {author}"
version = ".".join(sysid_nn.__version__.split(".")[:2])
release = sysid_nn.__version__

# -- General configuration ---------------------------------------------------

extensions = [
    "sphinx.ext.autodoc",
    "sphinx.ext.autosummary",
    "sphinx.ext.intersphinx",
    "sphinx.ext.mathjax",
    "numpydoc",
    "sphinx_gallery.gen_gallery",
]

templates_path = ["_templates"]
exclude_patterns = [
    "_build",
    "_intersphinx",
    "Thumbs.db",
    ".DS_Store",
    # Fragments pulled in with ``.. include::``; they are not documents.
    "api/*.rst",
    "generated/api_index.rst",
    # Index files written by sphinx-gallery next to each gallery.
    "auto_examples/*.ipynb",
    "auto_examples/*.py",
    "auto_examples/*.zip",
    "auto_examples/*.md5",
    "auto_examples/*.json",
]
root_doc = "index"
default_role = "literal"
pygments_style = "sphinx"
math_number_all = False
math_eqref_format = "({number})"

# MathJax is loaded by the reader's browser from a CDN; a local copy can be
# used instead (offline reading) by pointing this variable to it.
if os.environ.get("SYSID_NN_DOCS_MATHJAX_PATH"):
    mathjax_path = os.environ["SYSID_NN_DOCS_MATHJAX_PATH"]

# -- autodoc / autosummary / numpydoc -----------------------------------------

autosummary_generate = True
autosummary_generate_overwrite = True
autosummary_imported_members = False
autodoc_typehints = "none"
autodoc_member_order = "groupwise"

# Summaries often cite the paper ("... (paper eq. 13-15)."): do not let the
# summary tables of autosummary cut the first sentence after "eq.".
import sphinx.ext.autosummary as _autosummary

_autosummary.WELL_KNOWN_ABBREVIATIONS = (
    *_autosummary.WELL_KNOWN_ABBREVIATIONS,
    "eq.",
    "eqs.",
    "fig.",
    "figs.",
    "cf.",
)

numpydoc_show_class_members = False
numpydoc_class_members_toctree = False
numpydoc_attributes_as_param_list = True
numpydoc_xref_param_type = False
# The build fails on the most basic defects; tests/test_docstrings.py enforces
# the full set of rules on the public API.
numpydoc_validation_checks = {"GL08", "GL06", "GL07", "PR02"}
numpydoc_validation_exclude = {
    r"\.__init__$",
    r"\.set_\w+_request$",
    r"\.get_metadata_routing$",
    # Members documented by Python or scikit-learn, not by this project.
    r"\.with_traceback$",
    r"\.add_note$",
    # Module data documented by their ``#:`` comments; a read-only mapping
    # (mappingproxy) has no docstring of its own for numpydoc to find.
    r"\.PAPER_(TDL|ISSM)$",
}

# -- intersphinx (offline-safe) ------------------------------------------------

_INTERSPHINX_TARGETS = {
    "python": "https://docs.python.org/3/",
    "numpy": "https://numpy.org/doc/stable/",
    "scipy": "https://docs.scipy.org/doc/scipy/",
    "sklearn": "https://scikit-learn.org/stable/",
    "statsmodels": "https://www.statsmodels.org/stable/",
    "pandas": "https://pandas.pydata.org/docs/",
    "matplotlib": "https://matplotlib.org/stable/",
}


def _intersphinx_mapping() -> dict[str, tuple[str, str | None]]:
    """Return the inventories that can be read without surprises.

    A local copy ``docs/_intersphinx/<name>.inv`` is always used when present.
    Remote inventories are fetched only when ``SYSID_NN_DOCS_INTERSPHINX=1``;
    otherwise a project without a local copy is simply not cross-referenced,
    so an offline build raises no warning and downloads nothing.
    """
    allow_remote = os.environ.get("SYSID_NN_DOCS_INTERSPHINX", "") == "1"
    mapping = {}
    for name, url in _INTERSPHINX_TARGETS.items():
        local = INVENTORY_DIR / f"{name}.inv"
        if local.is_file():
            mapping[name] = (url, str(local))
        elif allow_remote:
            mapping[name] = (url, None)
    return mapping


intersphinx_mapping = _intersphinx_mapping()
intersphinx_timeout = 10

# -- API reference generated from ``__all__`` ----------------------------------

# Pages of the API reference: (page name, title, module, grouping of the names
# re-exported at the top level). The intro of each page is the hand-written
# fragment docs/api/<page>.rst when it exists, else the module docstring.
_TOP_LEVEL_GROUPS = {
    "Estimators": ["TDLRegressor", "ISSMRegressor"],
    "Data generation": ["HystereticOscillator", "ShearBuilding"],
    "Saving and export": ["save_model", "load_model", "export_onnx", "to_dlti"],
    "Warnings": ["DivergenceWarning"],
}
_API_PAGES = [
    ("sysid_nn", "Estimators and data generation", "sysid_nn"),
    ("excitation", "Excitation processes", "sysid_nn.excitation"),
    ("oscillator", "Hysteretic oscillator module", "sysid_nn.oscillator"),
    ("building", "Shear building module", "sysid_nn.building"),
    ("residuals", "Residual analysis", "sysid_nn.residuals"),
    ("metrics", "Metrics and scorers", "sysid_nn.metrics"),
    ("plotting", "Plotting", "sysid_nn.plotting"),
    ("study", "The paper's study", "sysid_nn.study"),
    ("uncertainty", "Confidence and prediction bands", "sysid_nn.uncertainty"),
    ("datasets", "Benchmark data sets", "sysid_nn.datasets"),
]


def _public_names(module) -> list[str]:
    """Names of ``module.__all__``; each is resolved, so a broken re-export fails."""
    names = list(getattr(module, "__all__", []))
    for name in names:
        getattr(module, name)
    return names


def _autosummary(module_name: str, names: list[str]) -> list[str]:
    lines = [
        f".. currentmodule:: {module_name}",
        "",
        ".. autosummary::",
        "   :toctree: ..",
        "   :nosignatures:",
        "",
    ]
    lines += [f"   {name}" for name in names]
    return [*lines, ""]


def _heading(text: str, char: str) -> list[str]:
    return [text, char * len(text), ""]


def _write_if_changed(path: Path, text: str) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    if not path.is_file() or path.read_text(encoding="utf-8") != text:
        path.write_text(text, encoding="utf-8")


def _write_api_pages() -> list[str]:
    """Write one page per importable public module and the index toctree."""
    api_dir = GENERATED_DIR / "api"
    written = []
    top_level = set(_public_names(sysid_nn))
    for page, title, module_name in _API_PAGES:
        module = importlib.import_module(module_name)
        names = _public_names(module)
        if module_name != "sysid_nn":
            # Names re-exported at the top level are documented there once.
            names = [
                name
                for name in names
                if not (
                    name in top_level
                    and getattr(sysid_nn, name) is getattr(module, name)
                )
            ]
        if not names:
            continue
        lines = [f".. _api_{page}:", "", *_heading(title, "=")]
        lines += [f".. automodule:: {module_name}", "   :no-members:", ""]
        intro = DOCS_DIR / "api" / f"{page}.rst"
        if intro.is_file():
            lines += [f".. include:: ../../api/{page}.rst", ""]
        if module_name == "sysid_nn":
            remaining = list(names)
            for group, members in _TOP_LEVEL_GROUPS.items():
                present = [name for name in members if name in remaining]
                if present:
                    lines += _heading(group, "-")
                    lines += _autosummary(module_name, present)
                    remaining = [name for name in remaining if name not in present]
            if remaining:
                lines += _heading("Other public names", "-")
                lines += _autosummary(module_name, remaining)
        else:
            lines += _autosummary(module_name, names)
        _write_if_changed(api_dir / f"{page}.rst", "\n".join(lines))
        written.append(page)
    for stale in api_dir.glob("*.rst"):
        if stale.stem not in written:
            stale.unlink()
    index = [".. toctree::", "   :maxdepth: 1", ""]
    index += [f"   generated/api/{page}" for page in written]
    _write_if_changed(GENERATED_DIR / "api_index.rst", "\n".join([*index, ""]))
    return written


API_PAGES_WRITTEN = _write_api_pages()

# -- sphinx-gallery ------------------------------------------------------------

sphinx_gallery_conf = {
    "examples_dirs": "../examples",
    # Reading order, not sphinx-gallery's default (by code length).
    "within_subsection_order": "_tutorial_order.TutorialOrder",
    "gallery_dirs": "auto_examples",
    "filename_pattern": r"/plot_",
    "ignore_pattern": r"__init__\.py",
    "image_scrapers": ("matplotlib",),
    "reset_modules": ("matplotlib",),
    "abort_on_example_error": True,
    "only_warn_on_example_error": False,
    "plot_gallery": "True",
    "download_all_examples": False,
    "remove_config_comments": True,
    "doc_module": ("sysid_nn",),
    "backreferences_dir": "generated/backreferences",
    "show_memory": False,
    "min_reported_time": 1,
    "show_signature": False,
    "matplotlib_animations": False,
    # The timing tables load jQuery and DataTables from a CDN; leave them out.
    "write_computation_times": False,
}

# -- HTML output ---------------------------------------------------------------

html_theme = "pydata_sphinx_theme"
html_title = f"sysid_nn {release}"
html_static_path: list[str] = []
html_show_sourcelink = False
html_theme_options = {
    "navigation_with_keys": False,
    "show_toc_level": 2,
    "header_links_before_dropdown": 6,
    "use_edit_page_button": False,
    "check_switcher": False,
    "analytics": {},
    "icon_links": [],
    "footer_start": ["copyright"],
    "footer_end": ["sphinx-version"],
    "secondary_sidebar_items": ["page-toc"],
}
html_context = {"default_mode": "light"}

# Matplotlib figures in docstrings or examples must not pop up windows.
warnings.filterwarnings(
    "ignore",
    category=UserWarning,
    message="Matplotlib is currently using agg",
)
