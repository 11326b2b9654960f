"""``python -m predisat``: the ``predisat`` command line (as the console script)."""

import sys

from predisat.cli import main

sys.exit(main())
