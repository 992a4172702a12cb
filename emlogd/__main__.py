"""``python -m emlogd`` runs the CLI."""

import sys

from emlogd.cli import main

sys.exit(main())
