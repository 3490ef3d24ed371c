"""Root conftest: settings every test and doctest of the package runs under."""

import os

# Figures are drawn off screen.
os.environ.setdefault("MPLBACKEND", "Agg")
# scikit-learn's estimator checks exercise array-API dispatch with NumPy
# inputs only when SciPy runs in array-API mode (read once at SciPy import).
os.environ.setdefault("SCIPY_ARRAY_API", "1")

import pytest


@pytest.fixture(autouse=True, scope="session")
def _compiled_kernels():
    """Compile the kernels once, silently, before any test runs a command.

    The commands announce a first run's compilation on stderr; a test that
    happens to run first would see that line among its expected output.
    """
    from sysid_nn._compile import prepare_kernels

    prepare_kernels(show=False)
