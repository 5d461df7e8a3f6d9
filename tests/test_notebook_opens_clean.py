"""An untouched course notebook opens in JupyterLab unmodified (issue 29), seen in Chromium.

JupyterLab writes the kernel's ``language_info`` into the notebook it opens; when the stored one differs (the
student notebooks used to keep the language's name only), the notebook is marked modified before the student has
done anything (jupyter/notebook issue 2123 is the same for another Python version). The test opens a generated
student notebook and, as a control that the check can fail, the same notebook with the name-only
``language_info``, and reads JupyterLab's dirty mark on their tabs once the kernel is idle.
"""

from __future__ import annotations

import json
import sys
import time

import nbformat
import pytest

import browser
from browser import launch_chromium, open_notebook
from nbtools import NOTEBOOKS

pytestmark = pytest.mark.slow

NOTEBOOK = NOTEBOOKS / "01_pinhole_projection.ipynb"




def _dirty_after_open(page, url: str) -> bool:
    open_notebook(page, url)
    time.sleep(3.0)  # the kernel's info arrives with its first idle; give the model time to take it in
    return page.locator(".lm-TabBar-tab.jp-mod-current.jp-mod-dirty").count() > 0


def test_an_untouched_student_notebook_opens_unmodified(tmp_path):
    nb = nbformat.read(str(NOTEBOOK), as_version=4)
    info = dict(nb.metadata.language_info)
    kernel = ".".join(map(str, sys.version_info[:3]))
    assert info.get("version") == kernel, (
        f"the stored language_info is for Python {info.get('version')}, this kernel is {kernel}: the solutions were "
        "executed with another Python, so JupyterLab would rewrite it here")
    stripped = tmp_path / "name_only.ipynb"
    nb.metadata.language_info = {"name": "python"}  # what release.py wrote before issue 29
    stripped.write_text(json.dumps(nb, indent=1))
    with browser.jupyterlab(tmp_path, [NOTEBOOK, stripped]) as (url, token, _root), \
            browser.sync_playwright_or_skip()() as p:
        chromium = launch_chromium(p)
        try:
            page = chromium.new_page(viewport={"width": 1200, "height": 900})
            control = _dirty_after_open(page, f"{url}/lab/tree/name_only.ipynb?token={token}")
            page = chromium.new_page(viewport={"width": 1200, "height": 900})
            course = _dirty_after_open(page, f"{url}/lab/tree/{NOTEBOOK.name}?token={token}")
        finally:
            chromium.close()
    assert control, "the control (language_info with the name only) was not marked modified: the check cannot see it"
    assert not course, f"{NOTEBOOK.name} opened as modified without a change"
