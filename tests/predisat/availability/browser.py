"""Headless Chromium for the report tests and ``scripts/report_screenshots.py``.

Debian's ``chromium`` and ``chromium-driver`` (``scripts/setup.sh --dev``) driven by selenium
with the system chromedriver: nothing is downloaded (selenium's own driver manager is never
asked, the machine may be offline). The browser starts with a fresh profile and no background
networking.
"""

from __future__ import annotations

import shutil
import tempfile
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Any
from urllib.parse import unquote, urlparse

__all__ = [
    "CHROMEDRIVER",
    "CHROMIUM",
    "PageFacts",
    "broken_local_links",
    "chromium_missing",
    "headless_chromium",
    "page_facts",
    "screenshot_sections",
]

CHROMIUM = Path("/usr/bin/chromium")
CHROMEDRIVER = Path("/usr/bin/chromedriver")
CHROMIUM_FLAGS = (
    "--headless",
    "--no-sandbox",
    "--disable-gpu",
    "--disable-quic",
    "--no-first-run",
    "--disable-background-networking",
    "--disable-component-update",
    "--disable-sync",
    "--hide-scrollbars",
)


def chromium_missing() -> str:
    """Why the browser tests cannot run ("" when they can)."""
    if not CHROMIUM.is_file() or not CHROMEDRIVER.is_file():
        return (
            f"{CHROMIUM} or {CHROMEDRIVER} is absent: install Debian's chromium and "
            "chromium-driver (scripts/setup.sh --dev)"
        )
    try:
        import selenium  # noqa: F401
    except ImportError:
        return "selenium is not installed: pip install -e '.[dev]'"
    return ""


@contextmanager
def headless_chromium(width: int = 1280, height: int = 900) -> Iterator[Any]:
    """A selenium WebDriver of the system's headless Chromium with a fresh profile."""
    from selenium import webdriver
    from selenium.webdriver.chrome.service import Service

    profile = tempfile.mkdtemp(prefix="predisat-chromium-")
    opts = webdriver.ChromeOptions()
    opts.binary_location = str(CHROMIUM)
    for flag in CHROMIUM_FLAGS:
        opts.add_argument(flag)
    opts.add_argument(f"--user-data-dir={profile}")
    opts.add_argument(f"--window-size={width},{height}")
    driver = webdriver.Chrome(service=Service(executable_path=str(CHROMEDRIVER)), options=opts)
    try:
        yield driver
    finally:
        driver.quit()
        shutil.rmtree(profile, ignore_errors=True)


@dataclass(frozen=True)
class PageFacts:
    """What the browser saw of a page (from the rendered DOM)."""

    figures: list[dict[str, Any]]  # per <figure>: id, caption text, img alt, img natural width
    links: list[str]  # every href and src, as written
    sections: list[str]  # ids of <section> elements, in order
    details_open: list[bool]  # open state of every <details>
    banner: str  # text of the synthetic-data banner ("" when none)


_FACTS_JS = """
const figs = [...document.querySelectorAll('figure')].map(f => {
  const img = f.querySelector('img');
  const cap = f.querySelector('figcaption');
  return {id: f.id, caption: cap ? cap.innerText.trim() : '',
          alt: img ? (img.getAttribute('alt') || '') : null,
          width: img ? img.naturalWidth : 0, complete: img ? img.complete : false};
});
const links = [...document.querySelectorAll('[href],[src]')].map(
  e => e.getAttribute('href') || e.getAttribute('src'));
const sections = [...document.querySelectorAll('section')].map(s => s.id);
const details = [...document.querySelectorAll('details')].map(d => d.open);
const b = document.querySelector('.synthetic');
return {figures: figs, links: links, sections: sections, details: details,
        banner: b ? b.innerText : ''};
"""


def page_facts(driver: Any, html_path: Path) -> PageFacts:
    """Open ``html_path`` and read its figures, links, sections and banner from the DOM."""
    driver.get(html_path.resolve().as_uri())
    d = driver.execute_script(_FACTS_JS)
    return PageFacts(d["figures"], d["links"], d["sections"], d["details"], d["banner"])


def broken_local_links(links: list[str], html_path: Path) -> list[str]:
    """The local hrefs/srcs of a page that name no existing file (data: and #anchors pass)."""
    bad = []
    for link in links:
        u = urlparse(link)
        if u.scheme == "data" or link.startswith("#"):
            continue
        if u.scheme in ("http", "https") or link.startswith("//"):
            bad.append(f"{link} (remote: the report must load nothing)")
            continue
        path = Path(unquote(u.path)) if u.scheme == "file" else html_path.parent / unquote(u.path)
        if not path.exists():
            bad.append(link)
    return bad


def screenshot_sections(driver: Any, html_path: Path, out_dir: Path, prefix: str) -> list[Path]:
    """One PNG per ``<section>`` of the page (``<prefix>_<section id>.png``) in ``out_dir``."""
    from selenium.webdriver.common.by import By

    driver.get(html_path.resolve().as_uri())
    out_dir.mkdir(parents=True, exist_ok=True)
    shots = []
    for el in driver.find_elements(By.CSS_SELECTOR, "section"):
        sid = el.get_attribute("id")
        path = out_dir / f"{prefix}_{sid}.png"
        driver.execute_script("arguments[0].scrollIntoView(true);", el)
        el.screenshot(str(path))
        shots.append(path)
    return shots
