"""Where the kit's own folders are (the checkout the package runs from)."""

from __future__ import annotations

from pathlib import Path


def repo_root() -> Path:
    """The kit checkout: the folder holding ``dtscal_lib/``, ``notebooks/``, ``data/``.

    With the editable install the README sets up, that is the parent of the package.
    A non-editable install has no checkout: then the current folder is used.
    """
    here = Path(__file__).resolve().parent.parent
    if (here / "pyproject.toml").exists() and (here / "dtscal_lib").is_dir():
        return here
    return Path.cwd()
