"""``python -m flagtrack.daemon`` runs the ``flagtrack`` command."""

import sys

from flagtrack.daemon.cli import main

sys.exit(main())
