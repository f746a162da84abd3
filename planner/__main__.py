"""``python -m planner`` runs the command-line interface."""

import sys

from planner.app.cli import main

sys.exit(main())
