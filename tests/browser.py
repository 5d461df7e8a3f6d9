"""Headless Chromium for the browser tests: Debian's /usr/bin/chromium driven by Playwright.

Playwright never downloads a browser here; ``scripts/install-browser.sh`` (run by the README's
test command) installs Debian's. Under CI (any spelling of CI=true) a missing browser is a
failure, elsewhere a skip.
"""

from __future__ import annotations

import contextlib
import os
import secrets
import shutil
import socket
import subprocess
import sys
from pathlib import Path

import pytest
from ci import in_ci  # noqa: F401 - the one CI rule; re-exported for the browser tests

CHROMIUM_ARGS = [
    "--headless=new", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
    "--disable-background-networking", "--disable-component-update", "--disable-sync",
]


def chromium_path() -> str:
    """Path of Debian's chromium; a skip locally, a failure under CI, when it is missing."""
    path = shutil.which("chromium") or shutil.which("chromium-browser")
    if path is None:
        msg = "Debian's chromium is not installed (run: bash scripts/install-browser.sh)"
        if in_ci():
            pytest.fail(msg)
        pytest.skip(msg)
    return path


def sync_playwright_or_skip():
    """Playwright's ``sync_playwright``; a skip locally, a failure under CI, when Playwright is not installed."""
    try:
        from playwright.sync_api import sync_playwright
    except ImportError:
        if in_ci():
            pytest.fail("playwright is not installed (pip install -e .[test])")
        pytest.skip("playwright is not installed (pip install -e .[test])")
    return sync_playwright


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@contextlib.contextmanager
def jupyterlab(tmp_path: Path, notebooks):
    """JupyterLab on 127.0.0.1 with a temporary root holding copies of ``notebooks``; yields (url, token, root)."""
    root = tmp_path / "root"
    root.mkdir()
    for nb in notebooks:
        shutil.copy(nb, root / Path(nb).name)
    port, token = free_port(), secrets.token_hex(16)
    env = dict(os.environ, HOME=str(tmp_path / "home"), JUPYTER_CONFIG_DIR=str(tmp_path / "jcfg"),
               JUPYTER_RUNTIME_DIR=str(tmp_path / "jrun"), JUPYTERLAB_WORKSPACES_DIR=str(tmp_path / "jws"))
    log = open(tmp_path / "jupyterlab.log", "w")
    proc = subprocess.Popen(
        [sys.executable, "-m", "jupyterlab", "--no-browser", "--ip=127.0.0.1", f"--port={port}",
         f"--IdentityProvider.token={token}", f"--ServerApp.root_dir={root}", "--ServerApp.open_browser=False",
         "--allow-root",
         "--LabApp.news_url=", "--LabApp.check_for_updates_class=jupyterlab.NeverCheckForUpdate"],
        cwd=root, env=env, stdout=log, stderr=subprocess.STDOUT)
    url = f"http://127.0.0.1:{port}"
    try:
        wait_until_it_answers(f"{url}/api/status?token={token}", proc, tmp_path / "jupyterlab.log", "JupyterLab")
        yield url, token, root
    finally:
        proc.terminate()
        try:
            proc.wait(timeout=20)
        except subprocess.TimeoutExpired:
            proc.kill()
        log.close()


def launch_chromium(playwright):
    """Launch headless Chromium with the flags this closed network needs; returns the Browser."""
    return playwright.chromium.launch(executable_path=chromium_path(), headless=True, args=CHROMIUM_ARGS)


def wait_until_it_answers(url: str, proc, log_path, what: str, *, safety_s: float = 180.0) -> None:
    """Wait until a server the test started answers ``url``; raise with the tail of its log when its process
    ends first (or after ``safety_s``, a safety net only: no test asserts how long a start takes)."""
    import time
    import urllib.request

    end = time.monotonic() + safety_s
    while True:
        try:
            urllib.request.urlopen(url, timeout=2).read()
            return
        except OSError:
            if proc.poll() is not None or time.monotonic() > end:
                raise RuntimeError(f"{what} did not start: {log_path.read_text()[-3000:]}") from None
            time.sleep(0.5)


def open_notebook(page, url: str, *, timeout_ms: int = 120_000, dialog_ms: int = 15_000) -> None:
    """Open a notebook in JupyterLab and wait until its kernel is idle; a fresh JupyterLab may ask once which
    kernel to use (the dialog's Select is clicked). The timeouts are safety nets, not assertions."""
    page.goto(url)
    page.wait_for_selector(".jp-Notebook .jp-Cell", timeout=timeout_ms)
    select = page.locator(".jp-Dialog button", has_text="Select")
    try:
        select.wait_for(timeout=dialog_ms)
        select.click()
    except Exception:  # no dialog: the kernel was chosen already
        pass
    page.wait_for_selector("#jp-main-statusbar :text('Idle')", timeout=timeout_ms)

