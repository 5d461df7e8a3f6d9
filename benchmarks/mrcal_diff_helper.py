"""mrcal side of ``benchmarks/bench_compare.py``: ``mrcal.projection_diff`` on two models, on Debian's Python.

Request (JSON on stdin)::

    {"models": [{"lensmodel": "LENSMODEL_OPENCV5", "intrinsics": [fx, fy, cx, cy, k1, ...],
                 "imagersize": [W, H]}, {...}], "gridn_width": 60}

Answer: ``{"difflen": [[...]] (gridn_height x gridn_width, pixels), "q0": [...], "Rt10": [[...]]}``, from
``mrcal.projection_diff(models, gridn_width=..., use_uncertainties=False)`` (the models carry no
optimization inputs, so mrcal fits the rotation over its default focus region, min(W, H)/6 around the centre,
at infinity).
"""

import json
import sys

import numpy as np


def main():
    try:
        import mrcal
    except ImportError as exc:
        json.dump({"error": f"cannot import mrcal on {sys.executable}: {exc} (run scripts/install-mrcal.sh)"},
                  sys.stdout)
        sys.exit(2)
    req = json.load(sys.stdin)
    models = [mrcal.cameramodel(intrinsics=(m["lensmodel"], np.asarray(m["intrinsics"], dtype=float)),
                                imagersize=np.asarray(m["imagersize"], dtype=np.int32)) for m in req["models"]]
    difflen, _, q0, Rt10 = mrcal.projection_diff(models, gridn_width=int(req.get("gridn_width", 60)),
                                                 use_uncertainties=False)
    json.dump({"difflen": np.where(np.isfinite(difflen), difflen, -1.0).tolist(), "q0": q0.tolist(),
               "Rt10": np.asarray(Rt10).tolist(), "mrcal": getattr(mrcal, "__version__", "2.2")}, sys.stdout)
    sys.stdout.write("\n")


if __name__ == "__main__":
    main()
