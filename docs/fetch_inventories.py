"""Download the intersphinx inventories used by the documentation.

Run once on a machine with network access::

    python docs/fetch_inventories.py

The inventories are written to ``docs/_intersphinx/<name>.inv``; ``conf.py``
uses every inventory found there, so later builds link to the documentation of
NumPy, SciPy, scikit-learn, statsmodels, pandas and Matplotlib without any
network access. Nothing is downloaded during a documentation build unless
``SYSID_NN_DOCS_INTERSPHINX=1`` is set.
"""

from __future__ import annotations

import argparse
import ast
import sys
import urllib.request
from pathlib import Path

DOCS_DIR = Path(__file__).resolve().parent


def _targets() -> dict[str, str]:
    """Read ``_INTERSPHINX_TARGETS`` from conf.py without executing it."""
    tree = ast.parse((DOCS_DIR / "conf.py").read_text(encoding="utf-8"))
    for node in tree.body:
        if isinstance(node, ast.Assign) and any(
            isinstance(t, ast.Name) and t.id == "_INTERSPHINX_TARGETS"
            for t in node.targets
        ):
            return ast.literal_eval(node.value)
    raise RuntimeError("conf.py defines no _INTERSPHINX_TARGETS")


def main(argv: list[str] | None = None) -> int:
    """Fetch the inventories; return the number of failures."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("names", nargs="*", help="projects to fetch (default: all)")
    parser.add_argument("--timeout", type=float, default=30.0)
    args = parser.parse_args(argv)
    targets = _targets()
    names = args.names or sorted(targets)
    out_dir = DOCS_DIR / "_intersphinx"
    out_dir.mkdir(exist_ok=True)
    failures = 0
    for name in names:
        url = targets[name].rstrip("/") + "/objects.inv"
        try:
            with urllib.request.urlopen(url, timeout=args.timeout) as response:
                data = response.read()
        except OSError as exc:
            print(f"{name}: failed ({exc})", file=sys.stderr)
            failures += 1
            continue
        if not data.startswith(b"# Sphinx inventory version"):
            print(f"{name}: {url} is not a Sphinx inventory", file=sys.stderr)
            failures += 1
            continue
        (out_dir / f"{name}.inv").write_bytes(data)
        print(f"{name}: {len(data)} bytes from {url}")
    return failures


if __name__ == "__main__":
    sys.exit(main())
