"""``python -m emlogd`` runs the CLI."""

import sys

from emlogd.entry import main

sys.exit(main())
