"""Calibration figures, the --report page and the CLI's verdict and warnings (dtscal_lib.report)."""

from __future__ import annotations

import io
import json
import re
import subprocess
import sys
from types import SimpleNamespace

import cv2
import numpy as np
import pytest
from matplotlib.figure import Figure

from dtscal_lib import camera, datasets, duckietown as dt, report
from dtscal_lib.boards import DUCKIETOWN_BOARD
from dtscal_lib.calibration import calibrate
from dtscal_lib.datasets import session_dir
from dtscal_lib.errors import DtscalError

OBJ = DUCKIETOWN_BOARD.object_points()


def _views(poses, noise=0.05, seed=0):
    rng = np.random.default_rng(seed)
    return [camera.project_points(OBJ, r, t, dt.default_K(), dt.default_dist()) + rng.normal(0, noise, (35, 2))
            for r, t in poses]


@pytest.fixture(scope="module")
def good():
    """The board poses of the shipped session (its ground truth), with corner noise: a good calibration."""
    frames = [f for f in datasets.load_truth()["intrinsics"]["frames"] if f["board_visible"]][::6]
    res = calibrate([OBJ] * len(frames), _views([(f["rvec"], f["tvec"]) for f in frames]), dt.IMAGE_SIZE)
    return res, res.quality()


@pytest.fixture(scope="module")
def parallel():
    poses = [([0.08, 0.02, 0.0], [-0.09, -0.06, 0.33]), ([0.0, 0.09, 0.05], [-0.12, -0.05, 0.35]),
             ([-0.06, -0.05, -0.04], [-0.08, -0.07, 0.31])]
    return calibrate([OBJ] * 3, _views(poses), dt.IMAGE_SIZE)


@pytest.mark.parametrize("name", list(report.FIGURES))
def test_every_figure_is_a_pyplot_free_figure(good, name):
    res, q = good
    fn = report.FIGURES[name][0]
    before = _pyplot_figures()
    fig = fn(res, q)
    assert isinstance(fig, Figure) and fig.axes
    assert _pyplot_figures() == before  # nothing registered with pyplot: safe in the CLI and the live UI
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=50)
    img = cv2.imdecode(np.frombuffer(buf.getvalue(), np.uint8), cv2.IMREAD_COLOR)
    assert img is not None and img.std() > 1.0  # drawn, not blank


def _pyplot_figures():
    mod = sys.modules.get("matplotlib.pyplot")
    return mod.get_fignums() if mod else []


@pytest.fixture(scope="module")
def one_bad_view():
    """The good session's poses with one view's corners 20x noisier: the verdict names that view."""
    frames = [f for f in datasets.load_truth()["intrinsics"]["frames"] if f["board_visible"]][::6]
    views = _views([(f["rvec"], f["tvec"]) for f in frames])
    rng = np.random.default_rng(5)
    views[3] = views[3] + rng.normal(0, 1.0, views[3].shape)  # 1 px against 0.05 px elsewhere
    res = calibrate([OBJ] * len(views), views, dt.IMAGE_SIZE)
    return res, res.quality()


def _red_bars(fig) -> list[int]:
    from matplotlib.colors import to_hex

    return [i for i, bar in enumerate(fig.axes[0].patches) if to_hex(bar.get_facecolor()) == report.BAD_COLOR.lower()]


def test_figures_show_the_verdict_and_compute_it_when_not_given(good, one_bad_view):
    res, q = one_bad_view
    named = sorted(v for f in q.findings if f.code == "outlier_views" for v in f.views)
    assert q.verdict != "good" and named == [3], (q.verdict, [(f.code, f.views) for f in q.findings])
    assert _red_bars(report.fig_view_rms(res, q)) == [3]  # the view the verdict names is the red one
    assert _red_bars(report.fig_view_rms(res)) == [3]  # the same verdict, computed by the figure itself
    assert _red_bars(report.fig_view_rms(*good)) == []  # a good calibration: nothing in red


def test_write_report_writes_the_figures_and_a_page_with_the_verdict(parallel, tmp_path):
    page = report.write_report(parallel, tmp_path / "rep", title="near-parallel <views>")
    html = page.read_text(encoding="utf-8")
    for name in report.FIGURES:
        assert f'src="{name}"' in html
        png = cv2.imread(str(tmp_path / "rep" / name))
        assert png is not None and png.shape[0] > 100
    assert re.search(r'id="verdict">bad<', html)
    assert "near-parallel &lt;views&gt;" in html  # text is escaped
    assert "tilt the board" in html  # the advice is on the page
    data = json.loads(re.search(r'<script type="application/json" id="quality">(.*?)</script>', html, re.S).group(1))
    assert data["verdict"] == "bad" and any(f["code"] == "parallel_views" for f in data["findings"])


def test_warnings_go_to_stderr_and_say_what_to_do(parallel, tmp_path):
    run = SimpleNamespace(result=parallel, robot="bot", source="test views", samples=3, quality=parallel.quality())
    err = io.StringIO()
    q = report.quality_for_run(run, tmp_path / "r", stream=err)
    lines = err.getvalue().splitlines()
    assert q.verdict == "bad" and len(lines) == len(q.findings) >= 2
    assert all(line.startswith("dtscal: warning: calibration ") for line in lines)
    assert any("tilt the board" in line for line in lines)
    assert q.report_path == tmp_path / "r" / "index.html" and q.report_path.exists()


def test_no_warning_when_the_verdict_is_good(good):
    res, _ = good
    err = io.StringIO()
    run = SimpleNamespace(result=res, robot="bot", source="s", samples=res.n_views, quality=res.quality())
    q = report.quality_for_run(run, None, stream=err)
    assert q.verdict == "good" and err.getvalue() == "" and q.report_path is None


@pytest.mark.slow
def test_report_page_from_the_command_line_loads_in_chromium(tmp_path):
    from browser import launch_chromium, in_ci

    try:
        from playwright.sync_api import sync_playwright
    except ImportError:
        if in_ci():
            pytest.fail("playwright is not installed (pip install -e .[test])")
        pytest.skip("playwright is not installed")
    out = tmp_path / "report"
    p = subprocess.run([sys.executable, "-m", "dtscal_lib.cli", "calibrate-intrinsics", "--source",
                        str(session_dir() / "intrinsics.bag"), "--no-write", "--json", "-q", "--report", str(out)],
                       capture_output=True, text=True, timeout=600)
    assert p.returncode == 0, p.stderr
    data = json.loads(p.stdout)
    assert data["quality"]["verdict"] == "good" and data["quality"]["warnings"] == []
    assert data["report"] == str(out / "index.html")
    assert "warning" not in p.stderr
    with sync_playwright() as pw:
        browser = launch_chromium(pw)
        try:
            page = browser.new_page()
            page.goto((out / "index.html").as_uri())
            page.wait_for_load_state("load")
            widths = page.eval_on_selector_all("img", "imgs => imgs.map(i => i.complete ? i.naturalWidth : 0)")
            verdict = page.inner_text("#verdict")
        finally:
            browser.close()
    assert len(widths) == len(report.FIGURES) and all(w > 0 for w in widths), widths
    assert verdict == "good"


def test_a_report_folder_that_cannot_be_made_is_a_clear_error(parallel, tmp_path):
    blocker = tmp_path / "taken"
    blocker.write_text("a file, not a folder")
    with pytest.raises(DtscalError, match="cannot create the report folder"):
        report.write_report(parallel, blocker / "rep")


def test_show_displays_png_images(good, monkeypatch):
    import IPython.display

    shown = []
    monkeypatch.setattr(IPython.display, "display", lambda obj: shown.append(obj))
    res, q = good
    report.show(report.fig_view_rms(res, q), report.fig_coverage(res, q))
    assert len(shown) == 2
    for img in shown:
        assert img.data[:8] == b"\x89PNG\r\n\x1a\n"
