"""Look at an HTML report as a person would: headless Chromium (Debian's chromium-headless-shell).

`make browser` (run by CI) installs it where the user is root; tests that need it skip,
saying so, where no Chromium is found.
"""
from __future__ import annotations

import re
import shutil
import subprocess
from pathlib import Path

NAMES = ("chromium-headless-shell", "chromium", "chromium-browser", "google-chrome")
FLAGS = ["--headless", "--no-sandbox", "--disable-gpu", "--hide-scrollbars"]
_PROBE = """<script>window.addEventListener('load', () => {
  const im = [...document.images];
  document.title = 'figures ' + im.filter(i => i.complete && i.naturalWidth > 0).length + '/' + im.length;
});</script>"""


def chromium() -> str | None:
    """Path of a headless-capable Chromium, or None."""
    return next((p for p in map(shutil.which, NAMES) if p), None)


def figures_loaded(html: Path, work: Path) -> tuple[int, int]:
    """(images decoded, images on the page) after Chromium loads ``html`` (a probed copy in ``work``)."""
    text = html.read_text()
    probed = work / f"probe_{html.parent.name}_{html.name}"
    probed.write_text(text.replace("</body>", _PROBE + "</body>") if "</body>" in text else text + _PROBE)
    out = subprocess.run([chromium(), *FLAGS, "--virtual-time-budget=5000", "--dump-dom", probed.as_uri()],
                         capture_output=True, text=True, timeout=120).stdout
    m = re.search(r"<title>figures (\d+)/(\d+)</title>", out)
    if not m:
        raise AssertionError(f"{html}: Chromium did not load the page:\n{out[:2000]}")
    return int(m.group(1)), int(m.group(2))


def screenshot(html: Path, png: Path, width: int = 1280, height: int = 4000) -> Path:
    """A PNG of the page as Chromium draws it at ``width`` x ``height`` px."""
    subprocess.run([chromium(), *FLAGS, f"--window-size={width},{height}", f"--screenshot={png}", html.as_uri()],
                   capture_output=True, text=True, timeout=120, check=True)
    return png
