"""``python -m facewrap.cli`` runs the ``facewrap`` command."""

import sys

from . import main

sys.exit(main())
