"""The report in a real browser: headless Chromium loads report.html from disk, without network.

Checks that the page has its sections, that its script ran to the end (``data-js="ready"``) with no
error (the page's own error hook counts them in ``data-js-errors``; Chromium's console log must be
empty too), and takes a screenshot, which must be a non-empty PNG.

Chromium comes from the Debian package ``chromium``, which ``.ci/run`` installs when it is missing:
installing belongs there alone, never to a test. Without it the test is skipped, and says why.
"""

from __future__ import annotations

import os
import re
import shutil
import subprocess

import pytest

from stressbots.report import SECTIONS

CANDIDATES = ("chromium", "chromium-browser", "google-chrome", "google-chrome-stable")


def _find() -> str | None:
    for name in CANDIDATES:
        path = shutil.which(name)
        if path:
            return path
    return "/usr/bin/chromium" if os.path.exists("/usr/bin/chromium") else None


@pytest.fixture(scope="module")
def chromium():
    path = _find()
    if path is None:
        pytest.skip("headless Chromium is not installed (Debian package `chromium`; .ci/run installs it)")
    return path


@pytest.fixture(scope="module")
def report(main_job):
    """The report of the shared main-job run (the example without noise; see conftest.main_job)."""
    result, out = main_job
    assert result.code == 0, result.err
    return out / "report.html"


def _chromium(binary: str, tmp_path, *args: str) -> subprocess.CompletedProcess:
    flags = [
        "--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run", "--disable-background-networking",
        "--disable-component-update", "--disable-sync", "--disable-extensions", "--disable-default-apps", "--mute-audio",
        f"--user-data-dir={tmp_path / 'profile'}", "--enable-logging=stderr", "--v=0",
    ]
    env = {k: v for k, v in os.environ.items() if not k.lower().endswith("_proxy")}
    return subprocess.run([binary, *flags, *args], capture_output=True, text=True, timeout=180, env=env, check=False)


@pytest.mark.slow
@pytest.mark.xdist_group("main_job")
def test_report_loads_in_headless_chromium_without_errors(chromium, report, tmp_path):
    shot = tmp_path / "report.png"
    url = report.resolve().as_uri()
    done = _chromium(chromium, tmp_path, "--dump-dom", f"--screenshot={shot}", "--window-size=1280,2000", url)
    dom = done.stdout
    assert done.returncode == 0, done.stderr[-3000:]
    # the page's sections, after the scripts ran
    for sid, heading in SECTIONS:
        assert re.search(rf'<section id="{sid}"', dom), sid
        assert heading in dom, heading
    tag = re.search(r"<html[^>]*>", dom)
    assert tag is not None
    html_tag = tag.group(0)
    assert 'data-js="ready"' in html_tag, html_tag  # the animation script ran to its end
    assert 'data-js-errors="0"' in html_tag, (html_tag, re.search(r'<pre id="js-errors"[^>]*>(.*?)</pre>', dom, re.S))
    # nothing on the browser console (the page logs nothing when all is well)
    console = [ln for ln in done.stderr.splitlines() if ":CONSOLE" in ln or "Uncaught" in ln]
    assert not console, console
    assert "frame 1/" in dom  # the animation drew its first frame
    if not shot.exists():  # some builds ignore --screenshot next to --dump-dom: take it on its own
        again = _chromium(chromium, tmp_path, f"--screenshot={shot}", "--window-size=1280,2000", url)
        assert again.returncode == 0, again.stderr[-3000:]
    data = shot.read_bytes()
    assert data[:8] == b"\x89PNG\r\n\x1a\n" and len(data) > 20_000
    from PIL import Image

    with Image.open(shot) as im:
        assert im.size == (1280, 2000)
        colours = im.convert("RGB").resize((64, 100)).getcolors(64 * 100)
        assert colours is not None and len(colours) > 20  # not a blank page
