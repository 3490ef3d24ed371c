"""Entry point for ``python -m sysid_nn``."""

from sysid_nn.cli import main

if __name__ == "__main__":
    raise SystemExit(main())
