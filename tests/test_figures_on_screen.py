"""What the text describes is on screen, its arrows point where the points move, and its alt text reaches the page
(issue 29, items 1, 2 and 5).

- Every figure a notebook cell builds is displayed: the kit's figure functions (those that return a figure) are
  called either as the cell's last expression or inside ``display(...)``, and the stored outputs hold the picture.
- Every figure the prose points at ("Left:", "the first figure", "(panel 2)", "the colour bar", ...) is on the page
  next to that text: the solution notebooks, as stored (nbval checks a re-run gives the same text), are rendered by
  nbconvert's HTML exporter and opened in Chromium; the figure must be an ``<img>`` in a code cell's output within
  two cells of the text, decoded, shown at 100 % and carrying its alt text in ``alt``.
- The alt text is the ``alt`` attribute in nbconvert's HTML and in JupyterLab (JupyterLab 4's PNG renderer and
  nbconvert's ``lab`` template write no ``alt`` for an ``image/png`` output; see ``dtscal_lib/figure.py``).
- An arrow of the distortion field and of the residual figure, read back from the drawn matplotlib ``Quiver``,
  ends on the screen where the displacement it stands for ends.
"""

from __future__ import annotations

import ast
import inspect
import re
from pathlib import Path
from types import SimpleNamespace

import cv2
import nbformat
import numpy as np
import pytest

from browser import launch_chromium, sync_playwright_or_skip
from dtscal_lib import camera as cam
from dtscal_lib import compare, report
from dtscal_lib.boards import DUCKIETOWN_BOARD
from dtscal_lib import duckietown as dt
from dtscal_lib.teaching import course
from nbtools import SOLUTIONS

COURSE = ["01_pinhole_projection.ipynb", "02_homography.ipynb", "03_intrinsic_calibration.ipynb",
          "03b_calibration_quality.ipynb", "04_distortion_rectification.ipynb", "05_extrinsic_calibration.ipynb"]

#: prose that points at a figure on the page: a panel by number, "Left:"/"Right:", "the (first) figure", "this plot",
#: "the map", "the arrows", "the colour bar" ("maps" alone is also 04's pixel maps, so only "the map" and "the maps
#: show" count). The line stating the expected time names activities ("the figures 25 minutes"), not a figure.
REFERS_TO_A_FIGURE = re.compile(
    r"\(panel \d\)|^\s*(left|right):|\b(the|this|these|first|second|each) (figures?|plots?|panels?|map|arrows?)\b"
    r"|\bthe maps show\b|\bcolour bar\b", re.IGNORECASE | re.MULTILINE)
#: "next to its text": the figure is in a code cell at most this many cells before or after the text
NEAR = 2
NO_ALT = "No description has been provided for this image"  # what nbconvert's classic template writes without one


def _figure_builders() -> set[str]:
    """Names of the kit's functions that return a figure (what a notebook cell builds and must display)."""
    names = set()
    for mod in (course, report, compare):
        for name, obj in vars(mod).items():
            if inspect.isfunction(obj) and "Figure" in str(inspect.signature(obj).return_annotation):
                names.add(name)
    return names - {"new_figure"}  # an empty canvas the cell draws on, shown by its last line


def _called_name(node: ast.AST) -> str | None:
    if isinstance(node, ast.Call):
        f = node.func
        return f.attr if isinstance(f, ast.Attribute) else f.id if isinstance(f, ast.Name) else None
    return None


def _undisplayed_figures(source: str, builders: set[str]) -> list[str]:
    """Figure-building calls of a cell that IPython does not display: not the cell's last expression, not inside
    ``display(...)``, and not bound to a name that is one of those."""
    tree = ast.parse(source)
    shown: set[int] = set()
    shown_names: set[str] = set()
    last = tree.body[-1] if tree.body else None
    if isinstance(last, ast.Expr):
        shown.add(id(last.value))
        if isinstance(last.value, ast.Name):
            shown_names.add(last.value.id)
    for node in ast.walk(tree):
        if _called_name(node) == "display":
            for arg in node.args:
                shown.add(id(arg))
                if isinstance(arg, ast.Name):
                    shown_names.add(arg.id)
    bound: dict[int, set[str]] = {}
    for node in ast.walk(tree):
        if isinstance(node, ast.Assign) and _called_name(node.value):
            targets = set()
            for t in node.targets:
                targets |= {n.id for n in ast.walk(t) if isinstance(n, ast.Name)}
            bound[id(node.value)] = targets
    missing = []
    for node in ast.walk(tree):
        name = _called_name(node)
        if name in builders and id(node) not in shown and not (bound.get(id(node), set()) & shown_names):
            missing.append(f"line {node.lineno}: {name}(...)")
    return missing


def _has_picture(cell) -> bool:
    return any("<img" in out.get("data", {}).get("text/html", "") or "image/png" in out.get("data", {})
               for out in cell.get("outputs", []))


def test_the_display_rule_itself_sees_a_figure_followed_by_a_print():
    builders = {"fig_view_rms"}
    assert _undisplayed_figures("f(1)\nfig_view_rms(r, q)\nprint(x)", builders) == ["line 2: fig_view_rms(...)"]
    assert _undisplayed_figures("print(x)\nfig_view_rms(r, q)", builders) == []
    assert _undisplayed_figures("display(fig_view_rms(r, q))\nprint(x)", builders) == []
    assert _undisplayed_figures("figure, s = fig_view_rms(r, q)\nprint(s)\nfigure", builders) == []
    assert _undisplayed_figures("figure, s = fig_view_rms(r, q)\nprint(s)", builders) == ["line 1: fig_view_rms(...)"]


@pytest.mark.parametrize("name", COURSE)
def test_every_figure_a_cell_builds_is_displayed_and_stored(name):
    builders = _figure_builders()
    assert {"plot_reprojection", "fig_view_rms", "plot_distortion_field", "show_images"} <= builders
    nb = nbformat.read(str(SOLUTIONS / name), as_version=4)
    problems = []
    for i, cell in enumerate(nb.cells):
        if cell.cell_type != "code":
            continue
        missing = _undisplayed_figures(cell.source, builders)
        if missing:
            problems.append(f"cell {i} builds a figure nothing displays: {missing}")
        elif any(_called_name(n) in builders for n in ast.walk(ast.parse(cell.source))) and not _has_picture(cell):
            problems.append(f"cell {i} builds a figure but stores no picture (re-execute the notebook)")
    assert not problems, f"{name}: " + "; ".join(problems)


def _figure_refs(nb) -> list[int]:
    refs = []
    for i, cell in enumerate(nb.cells):
        if cell.cell_type == "markdown":
            text = "\n".join(ln for ln in cell.source.splitlines() if not ln.lstrip("*").startswith("Expected time"))
            if REFERS_TO_A_FIGURE.search(text):
                refs.append(i)
    return refs


@pytest.fixture(scope="module")
def rendered_pages(tmp_path_factory):
    """Each solution notebook as nbconvert's HTML (its default ``lab`` template), as a file Chromium can open."""
    from nbconvert import HTMLExporter

    out = tmp_path_factory.mktemp("html")
    exporter = HTMLExporter()
    pages = {}
    for name in COURSE:
        body, _ = exporter.from_filename(str(SOLUTIONS / name))
        pages[name] = out / (Path(name).stem + ".html")
        pages[name].write_text(body, encoding="utf-8")
    return pages


@pytest.fixture(scope="module")
def chromium():
    """One headless Chromium for the file (Playwright's sync API runs one instance per thread)."""
    with sync_playwright_or_skip()() as p:
        browser = launch_chromium(p)
        yield browser
        browser.close()


@pytest.fixture(scope="module")
def chromium_page(chromium):
    return chromium.new_page(viewport={"width": 1280, "height": 900})


# per cell of the page, in order: its kind and every image in its outputs (decoded size, shown size, alt)
_CELLS_JS = """() => Array.from(document.querySelectorAll('main > .jp-Cell.jp-Notebook-cell')).map(c => ({
    markdown: c.classList.contains('jp-MarkdownCell'),
    images: Array.from(c.querySelectorAll('.jp-OutputArea img')).map(i => ({
        natural: i.naturalWidth, shown: i.getBoundingClientRect().width, alt: i.getAttribute('alt')}))}))"""


@pytest.mark.parametrize("name", COURSE)
def test_figures_the_text_refers_to_are_on_the_page_next_to_it_with_their_alt_text(name, rendered_pages,
                                                                                     chromium_page):
    nb = nbformat.read(str(SOLUTIONS / name), as_version=4)
    chromium_page.goto(rendered_pages[name].as_uri())
    chromium_page.wait_for_load_state("load")
    cells = chromium_page.evaluate(_CELLS_JS)
    assert len(cells) == len(nb.cells), f"{name}: the page shows {len(cells)} cells of {len(nb.cells)}"
    stored_alt = {i: [out["data"]["text/plain"] for out in cell.get("outputs", []) if "text/html" in out.get("data", {})
                      and "<img" in out["data"]["text/html"]] for i, cell in enumerate(nb.cells)}
    problems = []
    for i, cell in enumerate(cells):
        for k, img in enumerate(cell["images"]):
            where = f"cell {i}, image {k + 1}"
            if img["natural"] == 0:
                problems.append(f"{where}: not decoded")
            if not img["alt"] or img["alt"] == NO_ALT or len(img["alt"].split()) < 10:
                problems.append(f"{where}: alt {img['alt']!r}")
            elif img["alt"] not in stored_alt[i]:
                problems.append(f"{where}: alt is not the figure's alt text: {img['alt'][:80]!r}")
            if img["shown"] < img["natural"] - 1:  # squeezed: its labels are no longer at 100 %
                problems.append(f"{where}: shown {img['shown']:.0f} px wide of {img['natural']} px")
    refs = _figure_refs(nb)
    for i in refs:
        near = range(max(0, i - NEAR), min(len(cells), i + NEAR + 1))
        if not any(cells[j]["images"] and not cells[j]["markdown"] for j in near):
            said = REFERS_TO_A_FIGURE.search(nb.cells[i].source)[0]
            problems.append(f"markdown cell {i} refers to a figure ({said!r}); none is on the page within {NEAR} cells")
    assert refs or name == "03_intrinsic_calibration.ipynb", f"{name}: the rule finds no reference to a figure"
    assert not problems, f"{name}: " + "; ".join(problems)


def _one_figure_notebook(fig) -> nbformat.NotebookNode:
    """A notebook whose one code cell displayed ``fig`` as a kernel displays it (IPython's formatter)."""
    from IPython.core.formatters import DisplayFormatter

    data, metadata = DisplayFormatter().format(fig)
    nb = nbformat.v4.new_notebook()
    nb.cells = [nbformat.v4.new_code_cell("fig", outputs=[nbformat.v4.new_output(
        "execute_result", data=data, metadata=metadata, execution_count=1)])]
    return nb


def test_a_figures_alt_text_reaches_the_img_in_nbconvert_html_in_chromium(chromium_page, tmp_path):
    from nbconvert import HTMLExporter

    fig = course.plot_distortion_field(cam.distort_normalized, dt.default_K(), dt.default_dist(), step=64)
    for template in ("lab", "classic"):
        body, _ = HTMLExporter(template_name=template).from_notebook_node(_one_figure_notebook(fig))
        page = tmp_path / f"{template}.html"
        page.write_text(body, encoding="utf-8")
        chromium_page.goto(page.as_uri())
        imgs = chromium_page.evaluate("() => Array.from(document.images).map(i => [i.naturalWidth, i.alt])")
        assert imgs == [[fig.get_size_inches()[0] * fig.dpi, repr(fig)]], (template, imgs)
        assert fig.alt in repr(fig)


@pytest.mark.slow
def test_a_figures_alt_text_reaches_the_img_in_jupyterlab(tmp_path, chromium):
    """Stored in a notebook (untrusted: JupyterLab sanitizes its HTML) and opened in JupyterLab in Chromium."""
    from browser import jupyterlab, open_notebook

    fig = course.plot_distortion_field(cam.distort_normalized, dt.default_K(), dt.default_dist(), step=64)
    notebook = tmp_path / "one_figure.ipynb"
    nbformat.write(_one_figure_notebook(fig), str(notebook))
    with jupyterlab(tmp_path, [notebook]) as (url, token, _root):
        page = chromium.new_page(viewport={"width": 1280, "height": 900})
        open_notebook(page, f"{url}/lab/tree/{notebook.name}?token={token}")
        img = page.locator(".jp-OutputArea-output img")
        img.wait_for(timeout=60_000)
        alt, natural = img.evaluate("i => [i.getAttribute('alt'), i.naturalWidth]")
        page.close()
    assert alt == repr(fig) and natural == fig.get_size_inches()[0] * fig.dpi


def _drawn_arrows(fig) -> tuple[np.ndarray, np.ndarray, object]:
    """Tails and tips (display pixels, y up) of every arrow of the figure's Quiver, read back from its polygons."""
    from matplotlib.quiver import Quiver

    fig.canvas.draw()
    (q, ax), = [(c, ax) for ax in fig.axes for c in ax.collections if isinstance(c, Quiver)]
    tails = q.get_offset_transform().transform(q.get_offsets())
    tips = []
    for path, tail in zip(q.get_paths(), tails):
        verts = q.get_transform().transform(path.vertices)  # the arrow polygon about its tail, in display pixels
        tips.append(tail + verts[np.argmax(np.hypot(verts[:, 0], verts[:, 1]))])
    return tails, np.array(tips), ax


def test_the_distortion_arrow_at_48_48_points_down_right_where_the_lens_moves_the_point():
    K, dist = dt.default_K(), dt.default_dist()
    # where the lens puts the point a pinhole camera sees at pixel (48, 48): OpenCV's projection of its ray
    x = np.linalg.solve(K, [48.0, 48.0, 1.0])
    moved = cv2.projectPoints(x.reshape(1, 3), np.zeros(3), np.zeros(3), K, dist)[0].ravel()
    assert np.allclose(moved - 48.0, (69.1, 45.9), atol=0.05)  # down-right, towards the centre (issue 29)
    fig = course.plot_distortion_field(cam.distort_normalized, K, dist, step=32)
    tails, tips, ax = _drawn_arrows(fig)
    k = int(np.argmin(np.hypot(*(tails - ax.transData.transform([48.0, 48.0])).T)))
    want = ax.transData.transform(moved)  # where (48 + 69.1, 48 + 45.9) is on the screen
    drawn, expected = tips[k] - tails[k], want - tails[k]
    assert expected[1] < 0, "v grows downwards on the image: the arrow must point down on the screen"
    cos = drawn @ expected / np.linalg.norm(drawn) / np.linalg.norm(expected)
    assert cos > np.cos(np.radians(3)), f"arrow drawn towards {drawn}, the point moves towards {expected}"
    # the tip lands on the moved point: within 2 % of the 83 px displacement (the head's polygon is its own)
    assert np.linalg.norm(tips[k] - want) < 0.02 * np.linalg.norm(expected)


def test_a_residual_arrow_points_along_the_residual():
    views = SimpleNamespace(image_points=[np.array([[100.0, 100.0], [400.0, 300.0]])], size=(640, 480))
    residual = np.array([[4.0, 6.0], [-3.0, -2.0]])  # down-right and up-left on the image, px
    fig = course.plot_reprojection({"a fit": [residual]}, views, scale=5)
    tails, tips, ax = _drawn_arrows(fig)
    for uv, r in zip(views.image_points[0], residual):
        k = int(np.argmin(np.hypot(*(tails - ax.transData.transform(uv)).T)))
        want = ax.transData.transform(uv + 5 * r) - tails[k]
        drawn = tips[k] - tails[k]
        assert drawn @ want / np.linalg.norm(drawn) / np.linalg.norm(want) > np.cos(np.radians(3)), (uv, r, drawn)


def test_photo_panels_are_at_least_300_px_wide_and_labels_at_the_figures_text_size():
    frame = np.full((480, 640, 3), 90, np.uint8)
    figures = {f"{n} frames, {w} in": course.show_images([frame] * n, ["a frame"] * n, width=w)
               for n in (1, 2, 3, 4) for w in (3.0,)}  # 3.0 in: the narrowest a notebook asks for
    figures["views"] = course.show_views(SimpleNamespace(images=[frame] * 3, image_points=[], size=(640, 480),
                                                         source="three frames", n_views=3))
    board = np.zeros((280, 360), np.uint8)  # 02's fronto-parallel view of the board, 40 px a square
    corners = DUCKIETOWN_BOARD.object_points()[:, :2] * 4000 + 100  # any 7x5 grid in the frame
    figures["warp"] = course.warp_figure(frame[..., 0], corners, board)
    ground = course.show_ground_result(frame, dt.default_H(), None)
    figures["ground"] = ground
    narrow = []
    for what, fig in figures.items():
        fig.canvas.draw()
        for ax in fig.axes:
            if ax.images and ax.get_window_extent().width < 300:  # issue 29: 185-230 px was too small to read
                narrow.append(f"{what}: {ax.get_window_extent().width:.0f} px")
    assert not narrow, narrow
    # 05's grid labels: as large as the kit's own figure text (9 pt at 80 dpi = 10 px), not 6 px inside the frame
    labels = [t for t in ground.axes[0].texts if t.get_text().isdigit()]
    assert {"20", "30"} <= {t.get_text() for t in labels}
    assert min(t.get_fontsize() * ground.dpi / 72 for t in labels) >= 10
