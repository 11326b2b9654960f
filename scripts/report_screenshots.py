"""Screenshots of an availability report, one per section, in headless Chromium.

    python scripts/report_screenshots.py OUT/availability/report.html docs/figures --prefix report

Uses Debian's chromium and chromium-driver (``scripts/setup.sh --dev``) through selenium, as
the report's browser test does (``tests/predisat/availability/browser.py``); nothing is
downloaded. Prints each file written and what the browser saw: every figure's caption and alt
text, the local links that name no file.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from tests.predisat.availability.browser import (
    broken_local_links,
    chromium_missing,
    headless_chromium,
    page_facts,
    screenshot_sections,
)


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("report", type=Path, help="report.html of `predisat availability`")
    p.add_argument("out", type=Path, help="folder for the PNG screenshots")
    p.add_argument("--prefix", default="report", help="file name prefix (default report)")
    p.add_argument("--width", type=int, default=1200, help="browser window width, px")
    args = p.parse_args()
    why = chromium_missing()
    if why:
        print(f"report_screenshots: {why}", file=sys.stderr)
        return 2
    if not args.report.is_file():
        print(f"report_screenshots: {args.report}: no such file", file=sys.stderr)
        return 2
    with headless_chromium(width=args.width) as driver:
        facts = page_facts(driver, args.report)
        shots = screenshot_sections(driver, args.report, args.out, args.prefix)
    for f in facts.figures:
        print(f"figure {f['id']}: {f['width']} px, alt {len(f['alt'] or '')} chars, caption "
              f"{len(f['caption'])} chars")  # fmt: skip
    print(f"broken local links: {broken_local_links(facts.links, args.report) or 'none'}")
    for s in shots:
        print(f"written {s} ({s.stat().st_size / 1000:.0f} kB)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
