"""``python -m hysid``: the command line."""

import sys

from hysid.cli import main

sys.exit(main())
