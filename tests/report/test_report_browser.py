"""The report page in a real browser (headless Chromium): plots render, no script errors, screenshot not blank.

Skipped, with the reason, only where no Chromium can be found (the README's set-up script installs
Debian's ``chromium`` package when missing).
"""

from __future__ import annotations

import os
import re
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest

from hdphm.report import write_report

SHOT = Path(__file__).resolve().parents[2] / "docs" / "report_screenshot.png"


def _chromium() -> str | None:
    for name in ("chromium", "chromium-browser", "google-chrome", "chrome"):
        p = shutil.which(name)
        if p:
            return p
    return None


def _run(browser: str, *args: str, tmp: Path) -> subprocess.CompletedProcess:
    cmd = [browser, "--headless=new", "--no-sandbox", "--disable-gpu", "--disable-dev-shm-usage",
           "--no-first-run", "--no-default-browser-check", f"--user-data-dir={tmp / 'profile'}",
           "--virtual-time-budget=15000", *args]
    return subprocess.run(cmd, capture_output=True, text=True, timeout=180)


@pytest.fixture(scope="module")
def browser():
    b = _chromium()
    if b is None:
        pytest.skip("no Chromium on this machine (bash scripts/setup.sh installs Debian's 'chromium' when apt works)")
    return b


def test_report_renders_in_chromium(browser, demo_like_run, tmp_path):
    page = write_report(demo_like_run, tmp_path / "report.html")
    dom = _run(browser, "--dump-dom", page.as_uri(), tmp=tmp_path)
    assert dom.returncode == 0, dom.stderr[-2000:]
    m = re.search(r'data-hdphm-plots="(\d+)/(\d+)"', dom.stdout)
    assert m, "the page's load handler did not run: " + dom.stdout[:500]
    ok, total = int(m.group(1)), int(m.group(2))
    assert total == 3 and ok == total, f"{ok} of {total} plots rendered"
    assert 'data-hdphm-errors="0"' in dom.stdout, "script errors on the page"
    assert "Uncaught" not in dom.stderr

    shot = tmp_path / "shot.png"
    r = _run(browser, f"--screenshot={shot}", "--window-size=1280,1800", page.as_uri(), tmp=tmp_path)
    assert r.returncode == 0 and shot.exists(), r.stderr[-2000:]
    import matplotlib.image as mpimg

    img = mpimg.imread(shot)[..., :3]
    assert img.shape[0] >= 1000 and img.shape[1] >= 1000
    # not blank: many distinct colours and real contrast (a white page has std 0)
    assert float(img.std()) > 0.05
    colours = np.unique((img.reshape(-1, 3) * 255).astype(np.uint8), axis=0)
    assert len(colours) > 50
    if os.environ.get("HDPHM_UPDATE_SCREENSHOT"):
        SHOT.parent.mkdir(parents=True, exist_ok=True)
        shutil.copyfile(shot, SHOT)
