"""Campaign of simulated train runs: ``locator campaign`` (:mod:`locator.campaign`).

Kept for the commands written before the command existed; the arguments are those of
``locator campaign --help`` (docs/locator.md, campaign), e.g.::

    .venv/bin/python scripts/locator_campaign.py --out campaign --runs-per-world 88 \\
        --workers 2 --demo demo_out --configs masks masks_budget masks_k2
"""

from __future__ import annotations

import sys

from locator.cli import main

if __name__ == "__main__":
    sys.exit(main(["campaign", *sys.argv[1:]]))
