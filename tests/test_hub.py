"""The course on a real JupyterHub, handed out by an nbgitpuller link: docs/ta.md's trial recipe, step by step.

The recipe (docs/ta.md, "A trial hub on one machine") is read from the page and followed: (1) the proxy,
configurable-http-proxy from npm (``scripts/install-hub.sh``, run by ``scripts/setup.sh --test``: checked here);
(2) the kit's wheel, built by the page's command in a copy of the kit (the checkout gets no build/ or egg-info);
(3) the users' environment ``hub-trial/env``, into which the wheel is installed; (4) the course repository, by the
page's own commands (``dtscal handout``, ``git init``/``add``/``commit``, the bare clone a git host keeps); (5) the
hub, ``jupyterhub -f scripts/jupyterhub_trial_config.py`` (the file the kit ships) with the page's variables; (6)
the link of the page's step 4 of the real hub, its placeholders filled as the trial says. One deviation, for the
machine's sake: step 3 installs only the wheel (no index, ``--no-deps``); JupyterLab, JupyterHub, nbgitpuller, OpenCV
and NumPy are borrowed from the test's own environment by a ``.pth`` line, as ``--system-site-packages`` would.

In Chromium the student logs in, follows the link, which clones the course (a URL ending in ``.git``) into
``~/dtscal-notebooks`` (``targetpath``: not ``course.git/``, the pitfall the page warns of) and opens notebook 01;
they write ``project_points`` and run the notebook: the self-check passes. Then notebook 06 runs on the recording
(the live calibrator fills its coverage bars and calibrates). The single-user server has no DTSCAL_DATA, no
checkout, no start.sh and no workspace: the kit finds its recording where the wheel put it
(``dtscal_lib/datasets.py``).
"""

from __future__ import annotations

import json
import os
import re
import shlex
import shutil
import subprocess
import sys
import sysconfig
import tempfile
import time
import urllib.parse
from pathlib import Path

import pytest
from browser import launch_chromium, open_notebook, wait_until_it_answers
from ci import missing
from course_server import _free_port

from nbtools import ROOT

pytestmark = pytest.mark.slow

CHP = ROOT / ".hub" / "node_modules" / ".bin" / "configurable-http-proxy"
USER = "ada"
STUDENT_CODE = '''def project_points(K, R, t, X):
    X = np.asarray(X, dtype=np.float64)
    cam = X @ np.asarray(R, dtype=np.float64).T + np.asarray(t, dtype=np.float64).reshape(1, 3)
    uvw = cam @ np.asarray(K, dtype=np.float64).T
    return uvw[:, :2] / uvw[:, 2:3]
'''


def _run(*cmd, **kw) -> subprocess.CompletedProcess:
    out = subprocess.run([str(c) for c in cmd], capture_output=True, text=True, timeout=600, **kw)
    assert out.returncode == 0, f"{cmd}: {out.stdout[-2000:]}{out.stderr[-2000:]}"
    return out


def _recipe() -> dict[int, list[str]]:
    """docs/ta.md's trial recipe: its command lines by step number (a line without a number: the step above's)."""
    page = (ROOT / "docs" / "ta.md").read_text()
    section = page.split("### A trial hub on one machine", 1)[1]
    block = section.split("```bash\n", 1)[1].split("```", 1)[0]
    steps, step = {}, 0
    for line in block.splitlines():
        number = re.search(r"#\s+(\d)\.", line)
        step = int(number.group(1)) if number else step
        steps.setdefault(step, []).append(re.sub(r"\s+#\s.*$", "", line).strip())
    assert sorted(steps) == [1, 2, 3, 4, 5], steps
    link = re.search(r"^\s*(https://HUB/hub/user-redirect/git-pull\?\S+)$", page, re.M).group(1)
    steps[6] = [link]
    return steps


def _hub_env(tmp: Path, steps: dict) -> Path:
    """Steps 2 and 3: the kit's wheel, installed into hub-trial/env (the rest borrowed, see the module's text)."""
    assert steps[2] == ["python3 -m pip wheel . --no-deps -w dist/"], steps[2]
    src = tmp / "kit-src"  # build from a copy: the checkout gets no build/ or egg-info
    src.mkdir()
    for name in ("pyproject.toml", "README.md", "LICENSE"):
        shutil.copy(ROOT / name, src / name)
    shutil.copytree(ROOT / "dtscal_lib", src / "dtscal_lib", ignore=shutil.ignore_patterns("__pycache__"))
    (src / "data").mkdir()
    shutil.copy(ROOT / "data" / "README.md", src / "data" / "README.md")
    shutil.copytree(ROOT / "data" / "session", src / "data" / "session")
    _run(sys.executable, "-m", "pip", "wheel", ".", "--no-deps", "-q", "-w", "dist/", cwd=src)
    wheel = next((src / "dist").glob("dtscal-*.whl"))
    assert steps[3][0] == "python3 -m venv hub-trial/env" and "dist/dtscal-*.whl" in steps[3][1], steps[3]
    env = tmp / "hub-trial" / "env"
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


def _course_repo(tmp: Path, steps: dict) -> Path:
    """Step 4, the page's commands as they are (the kit's `dtscal` for `.venv/bin/dtscal`; a TA's git identity)."""
    env = dict(os.environ, GIT_AUTHOR_NAME="TA", GIT_AUTHOR_EMAIL="ta@example.org", GIT_COMMITTER_NAME="TA",
               GIT_COMMITTER_EMAIL="ta@example.org", PYTHONPATH=str(ROOT))  # this checkout's kit
    dtscal = f"{shlex.quote(sys.executable)} -m dtscal_lib.cli"
    for line in steps[4]:
        _run("bash", "-c", line.replace(".venv/bin/dtscal", dtscal), cwd=tmp, env=env)
    bare = tmp / "hub-trial" / "course.git"
    assert (bare / "HEAD").is_file() and bare.name.endswith(".git")  # the URL the pitfall is about
    return bare


@pytest.fixture(scope="module")
def hub(tmp_path_factory):
    for mod in ("jupyterhub", "nbgitpuller", "playwright"):
        try:
            __import__(mod)
        except ImportError:
            missing(f"{mod} is not installed (pip install -e '.[test]')")
    steps = _recipe()
    assert steps[1] == ["bash scripts/install-hub.sh"], steps[1]
    if not CHP.exists():
        missing(f"{CHP} is missing (run: bash scripts/install-hub.sh)")
    tmp = tmp_path_factory.mktemp("hub")
    env = _hub_env(tmp, steps)
    repo = _course_repo(tmp, steps)
    # step 5: the page's variables and config file; the port a free one; the hub's state where the page puts it
    words = shlex.split(steps[5][0])
    settings = dict(w.split("=", 1) for w in words if "=" in w and not w.startswith("-"))
    program, config = [w for w in words if "=" not in w][0], words[words.index("-f") + 1]
    assert program == "hub-trial/env/bin/jupyterhub" and (ROOT / config).is_file(), words
    port = _free_port()
    hub_env = {k: v for k, v in os.environ.items() if k != "DTSCAL_DATA"}
    hub_env.update(settings, HUB_PORT=str(port), HUB_DIR=str(tmp / "hub-trial"))
    log = open(tmp / "hub.log", "w")
    proc = subprocess.Popen([env / "bin" / "python", "-m", "jupyterhub", "-f", str(ROOT / config)],  # the env's hub
                            cwd=tmp, env=hub_env, stdout=log, stderr=subprocess.STDOUT)
    url = f"http://127.0.0.1:{port}"
    try:
        log.flush()
        wait_until_it_answers(f"{url}/hub/api/", proc, tmp / "hub.log", "JupyterHub")
        # step 6: the link of the page, its placeholders filled as the trial says
        link = steps[6][0].replace("https://HUB", url).replace(
            urllib.parse.quote("https://git.example.org/course/dtscal-notebooks.git", safe=""),
            urllib.parse.quote(repo.as_uri(), safe=""))
        assert urllib.parse.quote(repo.as_uri(), safe="") in link, link
        yield {"url": url, "env": env, "repo": repo, "home": tmp / "hub-trial" / "home" / USER, "tmp": tmp,
               "link": link, "password": settings["HUB_PASSWORD"]}
    finally:
        proc.terminate()
        try:
            proc.wait(timeout=30)
        except subprocess.TimeoutExpired:
            proc.kill()
        log.close()
        for pidfile in ("proxy.pid",):  # the proxy outlives a killed hub: stop it by its own pid
            p = tmp / "hub-trial" / pidfile
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

    url, home, link = hub["url"], hub["home"], hub["link"]
    shots = Path(tempfile.mkdtemp(prefix="dtscal-hub-screenshots-"))
    print(f"\nscreenshots: {shots}")
    with sync_playwright() as p:
        browser = launch_chromium(p)
        page = browser.new_page(viewport={"width": 1400, "height": 1000})
        try:
            page.goto(f"{url}/hub/login")
            page.fill("#username_input", USER)
            page.fill("#password_input", hub["password"])
            page.click("#login_submit")
            page.wait_for_load_state()
            _open(page, link)  # nbgitpuller clones the course into the home, then opens notebook 01
            assert (home / "dtscal-notebooks" / "01_pinhole_projection.ipynb").is_file()
            assert (home / "dtscal-notebooks" / ".git").is_dir() and not (home / "course.git").exists()
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
            saved = home / "dtscal-notebooks" / "01_pinhole_projection.ipynb"
            assert "uvw[:, :2] / uvw[:, 2:3]" in saved.read_text()  # the student's code, saved in their home
            assert _errors(saved) == []
            assert "[x] project_points" in saved.read_text()  # the self-check's verdict, stored with the notebook

            _open(page, f"{url}/user/{USER}/lab/tree/dtscal-notebooks/06_duckiebot_camera.ipynb")
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
