"""Root conftest: doctests of the package run with a non-interactive backend."""

import os

os.environ.setdefault("MPLBACKEND", "Agg")
