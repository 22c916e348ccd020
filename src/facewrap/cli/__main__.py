"""``python -m facewrap.cli`` runs the ``facewrap`` command."""

import sys

from facewrap.cli import main

if __name__ == "__main__":   # not again in a worker process that imports it
    sys.exit(main())
