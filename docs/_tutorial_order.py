"""Reading order of the tutorials in the gallery.

sphinx-gallery sorts examples by code length unless told otherwise; the
configuration names this class by its dotted path so that Sphinx can cache
the configuration (a function object there cannot be pickled).
"""

from __future__ import annotations

ORDER = [
    "plot_getting_started.py",
    "plot_generate_data.py",
    "plot_tdl_prediction_vs_simulation.py",
    "plot_issm.py",
    "plot_noisy_records.py",
    "plot_residual_analysis.py",
    "plot_grid_search.py",
    "plot_multistorey.py",
    "plot_monte_carlo.py",
    "plot_confidence_bands.py",
    "plot_csv_data.py",
    "plot_onnx_export.py",
    "plot_benchmark_in_ten_lines.py",
    "plot_dask.py",
]


class TutorialOrder:
    """Sort key: listed tutorials first, in order; any others alphabetically."""

    def __init__(self, src_dir: str) -> None:
        self.src_dir = src_dir

    def __call__(self, filename: str) -> str:
        position = ORDER.index(filename) if filename in ORDER else len(ORDER)
        return f"{position:03d}_{filename}"

    def __repr__(self) -> str:
        return f"{type(self).__name__}({self.src_dir!r})"
