"""``python -m blurtrap``: the same as the ``blurtrap`` command."""

import sys

from .cli import main

if __name__ == "__main__":
    sys.exit(main())
