"""``python -m predisat.cli``: the ``predisat`` command line (as ``python -m predisat``)."""

import sys

from predisat.cli import main

sys.exit(main())
