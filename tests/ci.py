"""One rule for "are we under CI?", shared by every test that needs an optional dependency.

Under CI a missing dependency (ROS, a browser, the bundled session, a test package) is a
failure, never a skip; elsewhere it is a skip. CI is recognised whatever the spelling of
its value: ``CI=true``, ``CI=TRUE``, ``CI=1``, ``CI=yes``, ``CI=on``.
"""

from __future__ import annotations

import os

import pytest

_TRUE = {"1", "true", "yes", "on"}


def in_ci() -> bool:
    """True when CI is set to a true value, whatever its spelling (true, TRUE, 1, yes, on)."""
    return os.environ.get("CI", "").strip().lower() in _TRUE


def missing(message: str) -> None:
    """A required thing is missing: fail under CI, skip elsewhere."""
    if in_ci():
        pytest.fail(f"{message} (CI must have it)")
    pytest.skip(message)
