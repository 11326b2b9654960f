"""The ``predisat`` command line: argument parsing only; every job is a library call.

* :mod:`predisat.cli.app` - the parser and the small subcommands (synth, export, evaluate-sky).
* :mod:`predisat.cli.process`, :mod:`predisat.cli.evaluate`, :mod:`predisat.cli.availability`,
  :mod:`predisat.cli.demo` - one module per larger subcommand: its options and their mapping
  onto the library (the demo also finds the steps other packages add).
* :mod:`predisat.cli.common` - what ``predisat`` and ``locator`` share: the ``main`` error
  wrapper, the track options, the kilometre range.
* :mod:`predisat.cli.args` - argument types checked at parse time.

Subcommands import the library modules they run inside their functions, so that ``--help`` and
argument errors answer without loading numba, OpenCV or the renderer.
"""

import sys

from predisat.clock import pinned_utc

try:  # before anything imports scipy: numpy's f2py reads it with int() and crashes unclearly
    pinned_utc()
except ValueError as exc:
    sys.exit(f"error: {exc}")

from predisat.cli.app import main

__all__ = ["main"]
