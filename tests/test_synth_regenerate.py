"""`dtscal synth` regenerates the shipped recording bit for bit (the data/ folder is reproducible)."""

import hashlib
import subprocess
import sys

import pytest

from dtscal_lib import datasets


@pytest.mark.slow
def test_dtscal_synth_reproduces_shipped_session(tmp_path):
    p = subprocess.run([sys.executable, "-m", "dtscal_lib.cli", "synth", "--out", str(tmp_path), "-q"],
                       capture_output=True, text=True, timeout=900)
    assert p.returncode == 0, p.stderr
    shipped = datasets.session_dir()
    for name in ("intrinsics.bag", "extrinsics.bag", "truth.yaml"):
        new = hashlib.sha256((tmp_path / "session" / name).read_bytes()).hexdigest()
        old = hashlib.sha256((shipped / name).read_bytes()).hexdigest()
        assert new == old, f"{name} differs from the shipped data/session/{name}"
