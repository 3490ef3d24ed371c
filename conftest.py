"""Root conftest: settings every test and doctest of the package runs under."""

import os

# Figures are drawn off screen.
os.environ.setdefault("MPLBACKEND", "Agg")
# scikit-learn's estimator checks exercise array-API dispatch with NumPy
# inputs only when SciPy runs in array-API mode (read once at SciPy import).
os.environ.setdefault("SCIPY_ARRAY_API", "1")
