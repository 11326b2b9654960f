"""The ``predisat`` command line: argument parsing only; every job is a library call.

* :mod:`predisat.cli.app` - the parser and the subcommands.
* :mod:`predisat.cli.args` - argument types checked at parse time, and the shared error
  wrapper of the ``predisat`` and ``locator`` entry points.
"""

from predisat.cli.app import main

__all__ = ["main"]
