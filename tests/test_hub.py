"""The course on a real JupyterHub, handed out by an nbgitpuller link, as most notebook courses run it.

A JupyterHub from PyPI (the [test] extra) with its proxy, configurable-http-proxy from npm
(``scripts/install-hub.sh`` puts it in ``.hub/node_modules``), JupyterHub's DummyAuthenticator and its
SimpleLocalProcessSpawner, all on 127.0.0.1. The single-user servers run in the hub's environment, a venv
made here into which the kit is pip-installed from a wheel (``pip wheel``, not editable); the kit's large
dependencies (OpenCV, NumPy, JupyterLab, JupyterHub, nbgitpuller) are borrowed from the test's own
environment by a ``.pth`` line, as ``--system-site-packages`` would, so no copy is installed. The course
is a bare git repository of the student notebooks (``notebooks/``), served as a file:// URL.

In Chromium the student logs in, follows the nbgitpuller link, which clones the notebooks into their
home and opens notebook 01; they write ``project_points`` and run the notebook: the self-check passes.
Then notebook 06 runs on the recording (the live calibrator fills its coverage bars and calibrates). The
single-user server has no DTSCAL_DATA, no checkout, no start.sh and no workspace: the kit finds its
recording where the wheel put it (``dtscal_lib/datasets.py``).
"""

from __future__ import annotations

import json
import os
import shutil
import socket
import subprocess
import sys
import sysconfig
import tempfile
import time
import urllib.parse
import urllib.request
from pathlib import Path

import pytest
from browser import launch_chromium, open_notebook, wait_until_it_answers
from ci import missing

from nbtools import ROOT

pytestmark = pytest.mark.slow

CHP = ROOT / ".hub" / "node_modules" / ".bin" / "configurable-http-proxy"
USER, PASSWORD = "ada", "not-a-secret"
STUDENT_CODE = '''def project_points(K, R, t, X):
    X = np.asarray(X, dtype=np.float64)
    cam = X @ np.asarray(R, dtype=np.float64).T + np.asarray(t, dtype=np.float64).reshape(1, 3)
    uvw = cam @ np.asarray(K, dtype=np.float64).T
    return uvw[:, :2] / uvw[:, 2:3]
'''


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _run(*cmd, **kw) -> subprocess.CompletedProcess:
    out = subprocess.run([str(c) for c in cmd], capture_output=True, text=True, timeout=600, **kw)
    assert out.returncode == 0, f"{cmd}: {out.stdout[-2000:]}{out.stderr[-2000:]}"
    return out


def _hub_env(tmp: Path) -> Path:
    """A venv holding the kit from a wheel; the other packages come from this test's environment."""
    src = tmp / "kit-src"  # build from a copy: the checkout gets no build/ or egg-info
    src.mkdir()
    for name in ("pyproject.toml", "README.md", "LICENSE"):
        shutil.copy(ROOT / name, src / name)
    shutil.copytree(ROOT / "dtscal_lib", src / "dtscal_lib", ignore=shutil.ignore_patterns("__pycache__"))
    (src / "data").mkdir()
    shutil.copy(ROOT / "data" / "README.md", src / "data" / "README.md")
    shutil.copytree(ROOT / "data" / "session", src / "data" / "session")
    _run(sys.executable, "-m", "pip", "wheel", str(src), "--no-deps", "-q", "-w", str(tmp / "wheel"))
    wheel = next((tmp / "wheel").glob("dtscal-*.whl"))
    env = tmp / "hubenv"
    _run(sys.executable, "-m", "venv", "--without-pip", str(env))
    py = env / "bin" / "python"
    site = Path(_run(py, "-c", "import sysconfig; print(sysconfig.get_paths()['purelib'])").stdout.strip())
    borrowed = dict.fromkeys([sysconfig.get_paths()["purelib"], sysconfig.get_paths()["platlib"]])
    (site / "_dtscal_test_borrowed.pth").write_text("".join(f"{p}\n" for p in borrowed))
    # JupyterLab's assets, the widgets' extension, nbgitpuller's server extension: where this environment has them
    (env / "share").mkdir(exist_ok=True)
    (env / "share" / "jupyter").symlink_to(Path(sys.prefix) / "share" / "jupyter")
    if (Path(sys.prefix) / "etc").is_dir():
        (env / "etc").symlink_to(Path(sys.prefix) / "etc")
    _run(sys.executable, "-m", "pip", "--python", str(py), "install", "--no-deps", "--no-index", "-q", str(wheel))
    return env


def _course_repo(tmp: Path) -> Path:
    """A bare repository of the student notebooks, as an instructor pushes the hand-out's notebooks."""
    work = tmp / "course-work"
    work.mkdir()
    for nb in sorted((ROOT / "notebooks").glob("*.ipynb")):
        shutil.copy(nb, work / nb.name)
    env = dict(os.environ, GIT_AUTHOR_NAME="TA", GIT_AUTHOR_EMAIL="ta@example.org", GIT_COMMITTER_NAME="TA",
               GIT_COMMITTER_EMAIL="ta@example.org")
    _run("git", "init", "-q", "-b", "main", cwd=work)
    _run("git", "add", "-A", cwd=work)
    _run("git", "commit", "-q", "-m", "course", cwd=work, env=env)
    bare = tmp / "course.git"
    _run("git", "clone", "-q", "--bare", str(work), str(bare))
    return bare


@pytest.fixture(scope="module")
def hub(tmp_path_factory):
    for mod in ("jupyterhub", "nbgitpuller", "playwright"):
        try:
            __import__(mod)
        except ImportError:
            missing(f"{mod} is not installed (pip install -e '.[test]')")
    if not CHP.exists():
        missing(f"{CHP} is missing (run: bash scripts/install-hub.sh)")
    tmp = tmp_path_factory.mktemp("hub")
    env = _hub_env(tmp)
    repo = _course_repo(tmp)
    homes = tmp / "home"
    homes.mkdir()
    (homes / USER).mkdir()
    port, hub_port, api_port = _free_port(), _free_port(), _free_port()
    root = os.geteuid() == 0
    (tmp / "jupyterhub_config.py").write_text(f'''
c = get_config()
c.JupyterHub.bind_url = "http://127.0.0.1:{port}"
c.JupyterHub.hub_ip = "127.0.0.1"
c.JupyterHub.hub_port = {hub_port}
c.ConfigurableHTTPProxy.api_url = "http://127.0.0.1:{api_port}"
c.ConfigurableHTTPProxy.command = [{str(CHP)!r}]
c.ConfigurableHTTPProxy.pid_file = {str(tmp / "proxy.pid")!r}
c.JupyterHub.db_url = "sqlite:///{tmp / "hub.sqlite"}"
c.JupyterHub.cookie_secret_file = {str(tmp / "cookie_secret")!r}
c.JupyterHub.pid_file = {str(tmp / "hub.pid")!r}
c.JupyterHub.authenticator_class = "dummy"
c.DummyAuthenticator.password = {PASSWORD!r}
c.Authenticator.allow_all = True
c.JupyterHub.spawner_class = "simple"
c.SimpleLocalProcessSpawner.home_dir_template = {str(homes / "{username}")!r}
c.Spawner.cmd = [{str(env / "bin" / "python")!r}, "-m", "jupyterhub.singleuser"]
c.Spawner.args = {["--allow-root"] if root else []!r} + ["--LabApp.news_url=",
    "--LabApp.check_for_updates_class=jupyterlab.NeverCheckForUpdate"]
c.Spawner.default_url = "/lab"
c.Spawner.start_timeout = 300
c.Spawner.http_timeout = 300
''')
    clean = {k: v for k, v in os.environ.items() if k != "DTSCAL_DATA"}
    log = open(tmp / "hub.log", "w")
    proc = subprocess.Popen([sys.executable, "-m", "jupyterhub", "-f", str(tmp / "jupyterhub_config.py")],
                            cwd=tmp, env=clean, stdout=log, stderr=subprocess.STDOUT)
    url = f"http://127.0.0.1:{port}"
    try:
        log.flush()
        wait_until_it_answers(f"{url}/hub/api/", proc, tmp / "hub.log", "JupyterHub")
        yield {"url": url, "env": env, "repo": repo, "home": homes / USER, "tmp": tmp}
    finally:
        proc.terminate()
        try:
            proc.wait(timeout=30)
        except subprocess.TimeoutExpired:
            proc.kill()
        log.close()
        for pidfile in ("proxy.pid",):  # the proxy outlives a killed hub: stop it by its own pid
            p = tmp / pidfile
            if p.is_file():
                try:
                    os.kill(int(p.read_text().strip()), 15)
                except (ValueError, OSError):
                    pass


def test_the_installed_kit_finds_its_recording_without_a_checkout(hub, tmp_path):
    env = {k: v for k, v in os.environ.items() if k != "DTSCAL_DATA"}
    out = _run(hub["env"] / "bin" / "python", "-c",
               "import dtscal_lib, dtscal_lib.datasets as d; print(dtscal_lib.__file__); print(d.session_dir())",
               cwd=tmp_path, env=env).stdout.split("\n")
    assert out[0].startswith(str(hub["env"])), out  # the wheel's copy, not this checkout (not editable)
    assert Path(out[1]) == hub["env"] / "share" / "dtscal" / "data" / "session", out
    assert (Path(out[1]) / "intrinsics.bag").stat().st_size == (ROOT / "data/session/intrinsics.bag").stat().st_size


def _open(page, url):
    open_notebook(page, url, timeout_ms=240_000, dialog_ms=10_000)  # the single-user server starts first


def _run_all_and_save(page):
    page.locator(".lm-MenuBar-itemLabel", has_text="Run").first.click()
    page.locator(".lm-Menu-itemLabel", has_text="Run All Cells").first.click()


def _errors(path: Path) -> list[str]:
    nb = json.loads(path.read_text())
    return [f"{o.get('ename')}: {o.get('evalue')}" for c in nb["cells"] if c["cell_type"] == "code"
            for o in c.get("outputs", []) if o.get("output_type") == "error"]


def test_student_on_the_hub_follows_the_nbgitpuller_link_and_runs_notebooks_01_and_06(hub):
    from playwright.sync_api import sync_playwright

    url, home = hub["url"], hub["home"]
    link = f"{url}/hub/user-redirect/git-pull?" + urllib.parse.urlencode({
        "repo": hub["repo"].as_uri(), "branch": "main", "targetpath": "course",
        "urlpath": "lab/tree/course/01_pinhole_projection.ipynb"})
    shots = Path(tempfile.mkdtemp(prefix="dtscal-hub-screenshots-"))
    print(f"\nscreenshots: {shots}")
    with sync_playwright() as p:
        browser = launch_chromium(p)
        page = browser.new_page(viewport={"width": 1400, "height": 1000})
        try:
            page.goto(f"{url}/hub/login")
            page.fill("#username_input", USER)
            page.fill("#password_input", PASSWORD)
            page.click("#login_submit")
            page.wait_for_load_state()
            _open(page, link)  # nbgitpuller clones the course into the home, then opens notebook 01
            assert (home / "course" / "01_pinhole_projection.ipynb").is_file()
            assert (home / "course" / ".git").is_dir()
            page.screenshot(path=str(shots / "01_opened.png"))
            editor = page.locator(".jp-CodeCell", has_text="def project_points").locator(".cm-content").first
            editor.click()
            page.keyboard.press("Control+a")
            page.keyboard.insert_text(STUDENT_CODE)
            _run_all_and_save(page)
            page.wait_for_selector(".jp-OutputArea-output:has-text('[x] project_points')", timeout=240_000)
            page.wait_for_selector("#jp-main-statusbar :text('Idle')", timeout=240_000)
            page.keyboard.press("Control+s")
            page.screenshot(path=str(shots / "02_selfcheck_passed.png"))
            time.sleep(2)
            saved = home / "course" / "01_pinhole_projection.ipynb"
            assert "uvw[:, :2] / uvw[:, 2:3]" in saved.read_text()  # the student's code, saved in their home
            assert _errors(saved) == []
            assert "[x] project_points" in saved.read_text()  # the self-check's verdict, stored with the notebook

            _open(page, f"{url}/user/{USER}/lab/tree/course/06_duckiebot_camera.ipynb")
            _run_all_and_save(page)
            page.wait_for_selector("img.dtscal-live-intrinsic", timeout=240_000)  # frames of the recording
            page.wait_for_function("document.querySelectorAll('.dtscal-bar[data-full=\"1\"]').length >= 4",
                                   timeout=300_000)
            page.screenshot(path=str(shots / "03_nb06_bars_full.png"))
            calibrate = page.locator("button:not([disabled])", has_text="CALIBRATE")
            calibrate.wait_for(timeout=120_000)
            calibrate.click()
            page.wait_for_selector(".dtscal-result", timeout=240_000)
            page.screenshot(path=str(shots / "04_nb06_calibrated.png"))
            text = page.locator(".dtscal-result").first.inner_text()
            assert "px" in text, text
        except Exception:
            page.screenshot(path=str(shots / "failure.png"))
            print((hub["tmp"] / "hub.log").read_text()[-4000:])
            raise
        finally:
            browser.close()
