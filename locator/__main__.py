"""``python -m locator``: the ``locator`` command line (as the console script)."""

import sys

from locator.cli import main

sys.exit(main())
