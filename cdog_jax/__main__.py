"""``python -m cdog_jax <command>``: the same command line as ``cdog-jax``."""

import sys

from .cli import main

if __name__ == "__main__":
    sys.exit(main())
