"""Notebook 06 in a real browser: JupyterLab on loopback, Debian's headless Chromium driven by Playwright.

Run all; the bars fill from the bundled recording; CALIBRATE, then COMMIT to a temporary
calibration folder; the YAML is within 0.3 % of the truth. The extrinsic tool then fits the
ground homography live; SAVE writes the best one, which maps the board corners within 3 mm.
While the bars fill, every live image the page loads is recorded with the arrival stamp the
calibrator puts on it: at least 20 are displayed, and in the order they arrived (an older frame
never replaces a newer one in the page). How long a frame takes from its arrival in the kernel to
its display is a figure of the machine's load, not a property of the code: it is printed here and
measured by ``benchmarks/bench_browser.py``, never asserted. Screenshots are kept in a folder under
the system's temporary folder (the path is printed).
"""

from __future__ import annotations

import tempfile
import time
from pathlib import Path

import numpy as np
import pytest

import browser
from browser import launch_chromium, open_notebook, sync_playwright_or_skip
from dtscal_lib import calib_files, datasets, ground

pytestmark = pytest.mark.slow

ROOT = Path(__file__).resolve().parent.parent
NOTEBOOK = ROOT / "notebooks" / "06_duckiebot_camera.ipynb"

#: installed once in the page: for every live image that loads, records [tool, arrival stamp (ms), load time,
#: time of the next animation frame (the one that paints it)]; ``window.__lat`` starts empty
LATENCY_JS = """() => {
  window.__lat = [];
  if (window.__latHook) return;
  window.__latHook = true;
  document.addEventListener('load', (e) => {
    const img = e.target;
    if (!img.classList || !img.classList.contains('dtscal-live')) return;
    const t = Date.now();
    const at = [...img.classList].find((k) => k.startsWith('dtscal-at-'));
    const tool = [...img.classList].find((k) => k.startsWith('dtscal-live-'));
    if (!at) return;
    requestAnimationFrame(() => window.__lat.push([tool ? tool.slice(12) : '', Number(at.slice(10)), t, Date.now()]));
  }, true);
}"""


def latency_summary(records: list, tool: str) -> tuple[np.ndarray, np.ndarray]:
    """(load - arrival, paint frame - arrival) in ms of the images of ``tool`` in ``window.__lat``."""
    r = [x for x in records if x[0] == tool]
    return (np.array([x[2] - x[1] for x in r], dtype=float), np.array([x[3] - x[1] for x in r], dtype=float))


def _playwright():
    return sync_playwright_or_skip()


@pytest.fixture()
def lab(tmp_path):
    """JupyterLab on 127.0.0.1 with a temporary root holding notebook 06; yields (url, token, root)."""
    with jupyterlab(tmp_path) as running:
        yield running


def jupyterlab(tmp_path: Path):
    """JupyterLab on 127.0.0.1 with a temporary root holding notebook 06 (also used by benchmarks/bench_browser.py)."""
    return browser.jupyterlab(tmp_path, [NOTEBOOK])


def _scroll_to(locator) -> None:
    """Scroll a live widget into view for a screenshot, best effort: the live tools re-render their
    panels with every frame, so the element found may be replaced before the scroll lands."""
    try:
        locator.scroll_into_view_if_needed(timeout=5_000)
    except Exception as exc:  # a screenshot framing, never the test's verdict
        print(f"(screenshot framing skipped: {type(exc).__name__})")


def _drive_notebook_06(url: str, token: str, shots: Path, calib_dir: Path) -> list:
    """One browser session: run notebook 06, CALIBRATE, COMMIT, extrinsic SAVE; returns the latencies (ms)."""
    shots.mkdir(parents=True, exist_ok=True)
    with _playwright()() as p:
        browser = launch_chromium(p)
        page = browser.new_page(viewport={"width": 1400, "height": 1000})
        try:
            open_notebook(page, f"{url}/lab/tree/{NOTEBOOK.name}?token={token}")
            page.locator(".lm-MenuBar-itemLabel", has_text="Run").first.click()
            page.locator(".lm-Menu-itemLabel", has_text="Run All Cells").first.click()
            # the calibrator's image arrives, then its bars fill from the recording; the latency is
            # measured from the first live image on (JupyterLab's start and Run All excluded) until they are full
            page.wait_for_selector("img.dtscal-live-intrinsic", timeout=120_000)
            page.evaluate(LATENCY_JS)
            page.screenshot(path=str(shots / "01_running.png"))
            page.wait_for_function("document.querySelectorAll('.dtscal-bar[data-full=\"1\"]').length >= 4",
                                   timeout=180_000)
            lat = page.evaluate("window.__lat")
            _scroll_to(page.locator(".dtscal-bar").first)
            page.screenshot(path=str(shots / "02_bars_full.png"))
            folder = page.locator(".widget-text", has=page.locator("label", has_text="folder"))
            folder.first.locator("input").fill(str(calib_dir))
            folder.first.locator("input").press("Tab")
            calibrate = page.locator("button:not([disabled])", has_text="CALIBRATE")
            calibrate.wait_for(timeout=60_000)
            calibrate.click()
            page.wait_for_selector(".dtscal-result", timeout=120_000)
            _scroll_to(page.locator(".dtscal-result"))
            page.screenshot(path=str(shots / "03_calibrated.png"))
            page.locator("button:not([disabled])", has_text="COMMIT").click()
            page.wait_for_selector(".dtscal-ok:has-text('COMMIT: wrote')", timeout=60_000)
            page.screenshot(path=str(shots / "04_committed.png"))

            # the extrinsic tool uses the new calibration at once
            page.wait_for_selector(".dtscal-fit", timeout=120_000)
            folder.nth(1).locator("input").fill(str(calib_dir))
            folder.nth(1).locator("input").press("Tab")
            time.sleep(1.0)  # a few more frames: the best fit so far
            page.get_by_role("button", name="SAVE", exact=True).nth(1).click()
            page.wait_for_selector(".dtscal-ok:has-text('SAVE: wrote')", timeout=60_000)
            _scroll_to(page.locator(".dtscal-fit"))
            page.screenshot(path=str(shots / "05_extrinsics_saved.png"))
        except Exception:
            page.screenshot(path=str(shots / "failure.png"))
            raise
        finally:
            browser.close()

    return lat


def test_notebook_06_calibrates_commits_and_saves_extrinsics_in_the_browser(lab, tmp_path):
    url, token, _root = lab
    # kept after the run (pytest rotates its own temporary folders): the path is printed
    shots = Path(tempfile.mkdtemp(prefix="dtscal-browser-screenshots-"))
    print(f"\nscreenshots: {shots}")
    calib_dir = tmp_path / "calibrations"
    truth = datasets.load_truth()
    lat = None
    for attempt in (1, 2):  # the live page re-renders with every frame: one retry on a browser-side race
        try:
            lat = _drive_notebook_06(url, token, shots / f"attempt{attempt}", calib_dir)
            break
        except Exception as exc:
            if attempt == 2:
                raise
            print(f"browser attempt 1 failed ({type(exc).__name__}: {str(exc)[:200]}); retrying once")
    K_true = np.asarray(truth["camera"]["K"])
    calib = calib_files.load_intrinsics(calib_dir / "camera_intrinsic" / "synthbot.yaml")
    for name, ij in (("fx", (0, 0)), ("fy", (1, 1)), ("cx", (0, 2)), ("cy", (1, 2))):
        assert abs(calib.K[ij] / K_true[ij] - 1) < 0.003, f"{name} = {calib.K[ij]:.3f}, truth {K_true[ij]:.3f}"

    H = calib_files.load_extrinsics(calib_dir / "camera_extrinsic" / "synthbot.yaml")
    ext = truth["extrinsics"]
    on_ground = ground.distorted_pixel_to_ground(calib.camera(), H, np.asarray(ext["frames"][0]["corners"]))
    err_mm = 1000 * np.linalg.norm(on_ground - np.asarray(ext["ground_points"]), axis=1)
    assert err_mm.max() < 3.0, f"worst board corner {err_mm.max():.2f} mm from the truth"

    # the acceptance figure: the calibrator's images, arrival in the kernel -> the animation frame that paints them
    for tool in ("intrinsic", "extrinsic"):
        loaded, painted = latency_summary(lat, tool)
        if len(painted):
            print(f"{tool} tool, frame arrival -> display in the browser over {len(painted)} images: painted median "
                  f"{np.median(painted):.1f} ms, p90 {np.percentile(painted, 90):.1f} ms (loaded: median "
                  f"{np.median(loaded):.1f} ms, p90 {np.percentile(loaded, 90):.1f} ms)")
    intrinsic = [x for x in lat if x[0] == "intrinsic"]
    assert len(intrinsic) >= 20, f"only {len(intrinsic)} frames displayed while the bars filled"
    arrivals = [x[1] for x in intrinsic]
    # the newest frame wins: images are displayed in the order the frames arrived, none goes back in time
    assert all(b >= a for a, b in zip(arrivals, arrivals[1:])), arrivals
    assert len(set(arrivals)) >= 20, arrivals  # distinct frames, not one image loaded again and again


def test_notebook_06_reaches_a_robot_over_dtps_and_commits_to_it(lab):
    """Notebook 06 with its one line set to a robot over DTPS (dtps-http's own server on loopback, publishing the
    recording on Duckietown's topic): the bars fill from the robot, CALIBRATE, COMMIT to *robot over DTPS*, and
    the robot's key-value store holds the file the notebook wrote (``tests/dtps_robot.py``)."""
    import json

    from dtps_robot import DtpsRobotServer

    url, token, root = lab
    calib_dir = root / "calibrations"
    with DtpsRobotServer(fps=30) as robot:
        nb = json.loads((root / NOTEBOOK.name).read_text())
        cell = next(c for c in nb["cells"] if c.get("id") == "nb06-03")
        text = "".join(cell["source"])
        text = text.replace('source = str(session_dir() / "intrinsics.bag")', f'source = "{robot.spec}"', 1)
        assert robot.spec in text
        cell["source"] = text
        # the robot's key-value store is on the test server, not on ROBOT's host:11411 (dtps_link.DtpsRobot)
        kernel_env = root / "kvstore.py"
        kernel_env.write_text(f"import os\nos.environ['DTSCAL_DTPS_KVSTORE'] = {robot.kvstore!r}\n")
        nb["cells"].insert(1, {"cell_type": "code", "id": "kvstore", "metadata": {}, "execution_count": None,
                               "outputs": [], "source": "%run kvstore.py"})
        (root / NOTEBOOK.name).write_text(json.dumps(nb))
        shots = Path(tempfile.mkdtemp(prefix="dtscal-browser-dtps-"))
        print(f"\nscreenshots: {shots}")
        with _playwright()() as p:
            browser = launch_chromium(p)
            page = browser.new_page(viewport={"width": 1400, "height": 1000})
            try:
                open_notebook(page, f"{url}/lab/tree/{NOTEBOOK.name}?token={token}")
                page.locator(".lm-MenuBar-itemLabel", has_text="Run").first.click()
                page.locator(".lm-Menu-itemLabel", has_text="Run All Cells").first.click()
                page.wait_for_selector("img.dtscal-live-intrinsic", timeout=120_000)
                page.wait_for_function("document.querySelectorAll('.dtscal-bar[data-full=\"1\"]').length >= 4",
                                       timeout=240_000)
                calibrate = page.locator("button:not([disabled])", has_text="CALIBRATE")
                calibrate.wait_for(timeout=60_000)
                calibrate.click()
                page.wait_for_selector(".dtscal-result", timeout=120_000)
                page.locator("button:not([disabled])", has_text="COMMIT").click()
                page.wait_for_selector(".dtscal-ok:has-text('COMMIT to testbot: stored as')", timeout=60_000)
                page.screenshot(path=str(shots / "committed_over_dtps.png"))
            except Exception:
                page.screenshot(path=str(shots / "failure.png"))
                raise
            finally:
                browser.close()
        stored = robot.stored.get("camera_intrinsic")
    calib = calib_files.load_intrinsics(calib_dir / "camera_intrinsic" / "testbot.yaml")
    assert stored == calib.to_dict()
    K_true = np.asarray(datasets.load_truth()["camera"]["K"])
    assert abs(calib.K[0, 0] / K_true[0, 0] - 1) < 0.003, calib.K
