"""Tolerances of the noisy checks, derived from the spread of the accepted formulations.

A noisy check (noisy homographies, noisy correspondences) is judged against the ground
truth the case was drawn from, never against the reference's own noisy estimate. How far
from the truth a *correct* answer may land depends on the noise and on which correct
formulation the student chose (H as given, H / H[2, 2], H / its spectral or Frobenius
norm, rows of V normalized, SVD of A or eigh of A^T A, closed form or Cholesky, lambda
from one column or the mean of two...). This module holds those formulations and derives,
by Monte Carlo over the case generator's noise (``SEEDS`` fresh draws of the same check
parameters, every formulation on each), the largest error any of them reaches; the
tolerance is that maximum times ``MARGIN``. A correct formulation then fails on fewer
than 1 draw in ``SEEDS`` (the tests re-check this on other seeds).

The derived numbers are stored with the cases, in ``grading/tolerances.json`` (next to
``grading/cases.py``); regenerate them after changing a noisy check's parameters::

    python -m dtscal_lib.grading.tolerances --write      # ~3 min on one core

A noisy check whose parameters have no stored tolerance is refused (MaterialError), so a
stale file can never grade.
"""

from __future__ import annotations

import argparse
import json
import math
import sys

import numpy as np

from .. import safe_write
from .checks import inputs_and_truth
from .material import find_material
from .metrics import (  # noqa: F401 - the metrics and the tolerance file, as this script's users know them
    NOISY_JUDGES,
    SHAPE_KEYS,
    K_max_px,
    load,
    pose_errors,
    rotation_deg,
    shape_key,
    tolerance_file,
    truth_rms_px,
)

#: Monte Carlo draws per noisy check, and the margin over the largest error they reach
SEEDS, MARGIN = 10000, 1.25
#: the draws use seeds SEED0, SEED0 + 1, ... (never a case's own seed range, 640xxx)
SEED0 = 10_000_000
#: the statistic each noisy judge compares with its tolerance, and its unit
STATISTICS = {
    "estimate_homography": ("truth_rms_px", "RMS distance between your H and the true H applied to the case's "
                                            "source points, in pixels"),
    "intrinsics_from_homographies": ("K_max_px", "largest difference between your K and the true K over fx, s, "
                                                 "cx, fy, cy, in pixels"),
    "extrinsics_from_homography": ("pose", "rotation angle between your R and the true R, in degrees; distance "
                                           "between your t and the true t relative to |t|"),
}


# --------------------------------------------------------------------------- accepted formulations
def _hartley_mean(p):
    c = p.mean(axis=0)
    s = math.sqrt(2) / np.mean(np.linalg.norm(p - c, axis=1))
    return np.array([[s, 0, -s * c[0]], [0, s, -s * c[1]], [0, 0, 1.0]])


def _hartley_rms(p):
    c = p.mean(axis=0)
    s = math.sqrt(2) / math.sqrt(np.mean(np.sum((p - c) ** 2, axis=1)))
    return np.array([[s, 0, -s * c[0]], [0, s, -s * c[1]], [0, 0, 1.0]])


def _per_axis(p):
    c, sd = p.mean(axis=0), p.std(axis=0)
    return np.array([[1 / sd[0], 0, -c[0] / sd[0]], [0, 1 / sd[1], -c[1] / sd[1]], [0, 0, 1.0]])


def _box(p):
    lo, hi = p.min(axis=0), p.max(axis=0)
    c, h = (lo + hi) / 2, (hi - lo) / 2
    return np.array([[1 / h[0], 0, -c[0] / h[0]], [0, 1 / h[1], -c[1] / h[1]], [0, 0, 1.0]])


def _dlt(src, dst, norm, solver="svd"):
    Ts, Td = norm(src), norm(dst)
    s = src @ Ts[:2, :2].T + Ts[:2, 2]
    d = dst @ Td[:2, :2].T + Td[:2, 2]
    n = len(s)
    A = np.zeros((2 * n, 9))
    A[0::2, 0:2], A[0::2, 2] = s, 1
    A[1::2, 3:5], A[1::2, 5] = s, 1
    A[0::2, 6:8], A[0::2, 8] = -d[:, :1] * s, -d[:, 0]
    A[1::2, 6:8], A[1::2, 8] = -d[:, 1:] * s, -d[:, 1]
    h = np.linalg.svd(A)[2][-1] if solver == "svd" else np.linalg.eigh(A.T @ A)[1][:, 0]
    H = np.linalg.inv(Td) @ h.reshape(3, 3) @ Ts
    return H / H[2, 2]


def _v(H, i, j):
    hi, hj = H[:, i], H[:, j]
    return np.array([hi[0] * hj[0], hi[0] * hj[1] + hi[1] * hj[0], hi[1] * hj[1],
                     hi[2] * hj[0] + hi[0] * hj[2], hi[2] * hj[1] + hi[1] * hj[2], hi[2] * hj[2]])


def _zhang(Hs, scale="frobenius", solver="svd", rows=False, closed=True):
    Vs = []
    for H in Hs:
        H = np.asarray(H, float)
        H = {"given": H, "h33": H / H[2, 2], "spectral": H / np.linalg.norm(H, 2),
             "frobenius": H / np.linalg.norm(H)}[scale]
        Vs += [_v(H, 0, 1), _v(H, 0, 0) - _v(H, 1, 1)]
    V = np.array(Vs)
    if rows:
        V = V / np.linalg.norm(V, axis=1, keepdims=True)
    b = np.linalg.svd(V)[2][-1] if solver == "svd" else np.linalg.eigh(V.T @ V)[1][:, 0]
    B11, B12, B22, B13, B23, B33 = b
    if not closed:  # B = lambda K^-T K^-1: Cholesky of B (sign fixed so B is positive definite)
        B = np.array([[B11, B12, B13], [B12, B22, B23], [B13, B23, B33]])
        B = B if B11 > 0 else -B
        L = np.linalg.cholesky(B)  # B = L L^T, L = K^-T / sqrt(lambda)
        K = np.linalg.inv(L.T)
        return K / K[2, 2]
    cy = (B12 * B13 - B11 * B23) / (B11 * B22 - B12 ** 2)
    lam = B33 - (B13 ** 2 + cy * (B12 * B13 - B11 * B23)) / B11
    fx = math.sqrt(lam / B11)
    fy = math.sqrt(lam * B11 / (B11 * B22 - B12 ** 2))
    s = -B12 * fx ** 2 * fy / lam
    cx = s * cy / fy - B13 * fx ** 2 / lam
    return np.array([[fx, s, cx], [0.0, fy, cy], [0.0, 0.0, 1.0]])


def _pose(K, H, lam_from="mean", separate=False):
    A = np.linalg.solve(np.asarray(K, float), np.asarray(H, float))
    n1, n2 = np.linalg.norm(A[:, 0]), np.linalg.norm(A[:, 1])
    lam = {"h1": 1 / n1, "mean": 2 / (n1 + n2), "geometric": 1 / math.sqrt(n1 * n2)}[lam_from]
    lam = -lam if A[2, 2] * lam < 0 else lam
    r1, r2 = (A[:, 0] / n1 * np.sign(lam), A[:, 1] / n2 * np.sign(lam)) if separate else (lam * A[:, 0],
                                                                                         lam * A[:, 1])
    U, _, Wt = np.linalg.svd(np.column_stack([r1, r2, np.cross(r1, r2)]))
    if np.linalg.det(U @ Wt) < 0:
        U[:, -1] = -U[:, -1]
    return U @ Wt, lam * A[:, 2]


#: the formulations the activity text or a textbook allows, per noisy function
FORMULATIONS = {
    "estimate_homography": {
        "Hartley sqrt(2) mean distance, SVD of A": lambda s, d: _dlt(s, d, _hartley_mean),
        "Hartley sqrt(2) mean distance, eigh of A^T A": lambda s, d: _dlt(s, d, _hartley_mean, "eigh"),
        "sqrt(2) RMS distance, SVD": lambda s, d: _dlt(s, d, _hartley_rms),
        "per-axis standardization, SVD": lambda s, d: _dlt(s, d, _per_axis),
        "bounding box to [-1, 1], eigh": lambda s, d: _dlt(s, d, _box, "eigh"),
    },
    "intrinsics_from_homographies": {
        "H / Frobenius norm, SVD, closed form": lambda Hs: _zhang(Hs),
        "H as given (Zhang's paper), SVD, closed form": lambda Hs: _zhang(Hs, "given"),
        "H / H[2, 2], eigh of V^T V, closed form": lambda Hs: _zhang(Hs, "h33", "eigh"),
        "H / spectral norm, SVD, Cholesky of B": lambda Hs: _zhang(Hs, "spectral", closed=False),
        "rows of V normalized, SVD, closed form": lambda Hs: _zhang(Hs, "given", rows=True),
        "H / Frobenius norm, eigh of V^T V, Cholesky of B": lambda Hs: _zhang(Hs, "frobenius", "eigh", closed=False),
    },
    "extrinsics_from_homography": {
        "lambda from the mean of |K^-1 h1|, |K^-1 h2|": lambda K, H: _pose(K, H, "mean"),
        "lambda = 1 / |K^-1 h1| (Zhang's paper)": lambda K, H: _pose(K, H, "h1"),
        "lambda from the geometric mean": lambda K, H: _pose(K, H, "geometric"),
        "r1 and r2 normalized separately": lambda K, H: _pose(K, H, "h1", separate=True),
    },
}


# --------------------------------------------------------------------------- statistics (the metrics: .metrics)
def errors_of(func: str, answer_of, args_list, truth) -> list[dict]:
    """The statistic of ``answer_of(*args)`` on each call of one drawn case."""
    out = []
    for args, true in zip(args_list, truth):
        try:
            got = answer_of(*args)
        except (ValueError, np.linalg.LinAlgError):
            out.append({"failed": 1.0})
            continue
        if func == "estimate_homography":
            out.append({"truth_rms_px": truth_rms_px(got, true, args[0])})
        elif func == "intrinsics_from_homographies":
            out.append({"K_max_px": K_max_px(got, true)})
        else:
            deg, rel = pose_errors(*got, *true)
            out.append({"deg": deg, "t_rel": rel})
    return out


def derive(func: str, spec: dict, seeds: int = SEEDS, seed0: int = SEED0) -> dict:
    """Monte Carlo over ``seeds`` draws of the case generator: the largest error of every
    accepted formulation, and the tolerance (largest of all times MARGIN)."""
    worst: dict[str, dict[str, float]] = {name: {} for name in FORMULATIONS[func]}
    all_values: dict[str, list[float]] = {}
    for k in range(seeds):
        args_list, truth = inputs_and_truth(func, spec, np.random.default_rng(seed0 + k))
        for name, f in FORMULATIONS[func].items():
            for e in errors_of(func, f, args_list, truth):
                if "failed" in e:
                    raise RuntimeError(f"{name} failed on draw {seed0 + k}: the case is ill-posed")
                for stat, v in e.items():
                    worst[name][stat] = max(worst[name].get(stat, 0.0), v)
                    all_values.setdefault(stat, []).append(v)
    top = {stat: max(w[stat] for w in worst.values()) for stat in all_values}
    return {
        "function": func,
        "tolerance": {stat: _round_up(MARGIN * v) for stat, v in top.items()},
        "max": {stat: float(f"{v:.4g}") for stat, v in top.items()},
        "q999": {stat: float(f"{np.quantile(v, 0.999):.4g}") for stat, v in all_values.items()},
        "median": {stat: float(f"{np.median(v):.4g}") for stat, v in all_values.items()},
        "per_formulation_max": {name: {s: float(f"{v:.4g}") for s, v in w.items()} for name, w in worst.items()},
        "seeds": seeds, "seed0": seed0, "margin": MARGIN,
        "command": "python -m dtscal_lib.grading.tolerances --write",
    }


def _round_up(x: float, digits: int = 3) -> float:
    """``x`` rounded UP to ``digits`` significant digits (a tolerance never shrinks by rounding)."""
    e = math.floor(math.log10(abs(x))) - digits + 1
    return float(f"{math.ceil(x / 10 ** e) * 10 ** e:.{digits}g}")


def noisy_specs(checks: dict) -> list[tuple[str, dict]]:
    return [(func, spec) for func, specs in checks.items() for spec in specs if spec.get("judge") in NOISY_JUDGES]


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--material", default=None, help="kit folder (default: this kit)")
    ap.add_argument("--seeds", type=int, default=SEEDS)
    ap.add_argument("--write", action="store_true", help="write grading/tolerances.json")
    a = ap.parse_args(argv)
    import runpy

    root = find_material(a.material)
    checks = runpy.run_path(str(root / "grading" / "cases.py"))["CHECKS"]
    out = {}
    for func, spec in noisy_specs(checks):
        key = shape_key(func, spec)
        if key in out:
            continue
        out[key] = derive(func, spec, a.seeds)
        out[key]["check"] = spec["name"]
        print(key, json.dumps(out[key]["tolerance"]), "max", json.dumps(out[key]["max"]), file=sys.stderr)
    if a.write:
        safe_write.write_text(tolerance_file(root), json.dumps(out, indent=1, sort_keys=True) + "\n",
                              what="tolerance file")
    else:
        print(json.dumps(out, indent=1, sort_keys=True))
    return 0


if __name__ == "__main__":
    sys.exit(main())
