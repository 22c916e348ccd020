"""``python -m facewrap.cli`` runs the ``facewrap`` command."""

import sys

from facewrap.cli import main

sys.exit(main())
