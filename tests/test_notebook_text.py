"""What the notebooks' prose says about their own output is true, on the solution path and on the stand-in path.

The solution path is read from the stored outputs of solutions/ (what nbval keeps in sync); the
stand-in path is what a student sees before writing any function: the generated notebook,
executed as handed out. Each claim below quotes the prose it checks.
"""

from __future__ import annotations

import math
import re

import nbformat
import pytest

from nbtools import SOLUTIONS, execute_student_once

NB01, NB02, NB03 = "01_pinhole_projection.ipynb", "02_homography.ipynb", "03_intrinsic_calibration.ipynb"
NB04, NB05 = "04_distortion_rectification.ipynb", "05_extrinsic_calibration.ipynb"


def _text(nb) -> str:
    out = []
    for cell in nb.cells:
        for o in cell.get("outputs", []):
            if o.get("output_type") == "stream":
                out.append(o["text"])
            elif "text/plain" in o.get("data", {}):
                out.append(o["data"]["text/plain"])
    return "\n".join(out)


def _prose(nb) -> str:
    return "\n".join(c.source for c in nb.cells if c.cell_type == "markdown")


def _table_err(text: str, label: str) -> float:
    """The 'max |err|' column of a row of course.intrinsics_table (the last printed one)."""
    rows = [line for line in text.splitlines() if line.startswith(label)]
    assert rows, f"no table row {label!r} in the output"
    return float(rows[-1].split()[-1].rstrip("px"))


def _code(nb) -> str:
    return "\n".join(c.source for c in nb.cells if c.cell_type == "code")


def _num(pattern: str, text: str, what: str) -> float:
    m = re.search(pattern, text)
    assert m, f"no {what} printed (pattern {pattern!r})"
    return float(m.group(1))


def _claims_01(nb) -> None:
    prose, text, code = _prose(nb), _text(nb), _code(nb)
    assert "the board leaves the image" not in prose  # issue 24: the pose helper keeps the board centred
    u0 = _num(r"yaw 60 deg at 0.5 m: the board spans u = (-?[0-9]+) to", text, "span at yaw 60")
    u1 = _num(r"yaw 60 deg at 0.5 m: the board spans u = -?[0-9]+ to (-?[0-9]+) px", text, "span at yaw 60")
    assert 0 <= u0 < u1 <= 640 and "the answer is 'inside'" in text
    # the explanation's numbers: the distance ratio, and the tilted board's depths (computed here, not read)
    assert "0.45 / 0.28 = 1.61" in code and round(0.45 / 0.28, 2) == 1.61
    assert _num(r"board width straight on: ([0-9.]+) px at 0.45 m", text, "width") > 0
    w45 = _num(r"board width straight on: ([0-9.]+) px", text, "width")
    w28 = _num(r"px at 0.45 m, ([0-9.]+) px at 0.28 m", text, "width")
    assert abs(w28 / w45 - 0.45 / 0.28) < 0.01
    half = 3 * 0.031 * math.sin(math.radians(40))  # half the board's 6 squares, turned by 40 deg
    assert f"{0.4 - half:.2f}-{0.4 + half:.2f} m" in code and f"{0.8 - half:.2f}-{0.8 + half:.2f} m" in code
    for d in (0.4, 0.8):
        assert f"a ratio of {(d + half) / (d - half):.2f}" in code
    assert f"about {100 * 2 * half:.0f} cm" in code
    # skew: the ROS bar is not the skew of K
    assert "nothing to do with\n  the skew $s$ of $K$" in prose


def _claims_02(nb) -> None:
    prose, text = _prose(nb), _text(nb)
    assert "agree to a fraction of\na percent" in prose
    rel = float(re.search(r"and OpenCV's: ([0-9.e+-]+) of the largest entry", text).group(1))
    assert rel < 0.01
    assert "A normalized fit stays at round-off level throughout." in prose
    assert re.search(r"normalized DLT.*: below 1e-08 px at every offset", text)
    assert "DLT without normalization: above 1e-06 px" in text
    assert "np.float64(" not in text
    # issue 24: A holds x, y, 1, ux, uy, u (no x squared), its range printed beside the claim
    assert "x^2 \\sim 10^{12}" not in prose and "x² ~ 10¹²" not in prose
    assert "range from 1 (the constant column) to $u\\,x$, a pixel times a coordinate of up to a million" in prose
    hi = _num(r"columns of the unnormalized A at offset 1e\+06: from 1 to ([0-9.e+]+)", text, "A's range")
    assert 1e8 <= hi < 1e10
    # the residual figure: magnified as the prose says, residuals far above the detector's 0.1 px
    assert "magnified 5×" in prose and "scale=5)" in _code(nb)
    assert "a tenth of a pixel, yet the residuals are much larger" in prose
    assert _num(r"RMS residual of .* on frame 304: ([0-9.]+) px", text, "residual RMS") > 0.5
    assert "swirl" not in prose
    # normalization as invariance, against the truth: the normalized column constant, the other not
    rows = re.findall(r"^\s+(-?[0-9.e+]+)\s+([0-9.e+-]+)\s+([0-9.]+)\s+([0-9.]+)$", text, re.MULTILINE)
    assert len(rows) >= 3
    assert len({r[2] for r in rows}) == 1 and len({r[3] for r in rows}) > 1
    assert "the normalized fit's error changes by 0.00 px" in text and "the answer is 'no'" in text
    assert "With noise of 1 px all three methods agree" not in prose
    # points off the plane: no residual on the plane, growing with the height
    lifted = [float(x) for x in re.findall(r"RMS residual of the best homography\s+([0-9.]+) px", text)]
    assert lifted[0] < 0.01 and all(a < b for a, b in zip(lifted, lifted[1:]))


def _claims_03(nb) -> None:
    prose, text = _prose(nb), _text(nb)
    assert "off by many pixels (the table's last column)" in prose
    err_cf = _table_err(text, "closed form, detected corners")
    assert err_cf > 5.0  # many: more than 25 times the full calibration's error (next assertion)
    band = "below 1 px" if err_cf < 1 else "1-10 px" if err_cf <= 10 else "above 10 px"
    assert f"the answer is '{band}'" in text
    assert "lands within a\nfraction of a pixel of the truth" in prose
    assert _table_err(text, "full calibration (with distortion)") < 0.5
    assert "On undistorted corners the closed form lands within about a pixel of the truth" in prose
    assert _table_err(text, "closed form, undistorted (truth)") < 1.0
    assert _table_err(text, "closed form, undistorted (full calib.)") < 1.0  # the label is not cut
    assert "The two rows differ by less than a tenth of a pixel" in prose
    assert abs(_table_err(text, "closed form, undistorted (full calib.)")
               - _table_err(text, "closed form, undistorted (truth)")) < 0.1
    assert "the same one OpenCV and ROS's `camera_calibration` use" not in prose  # initCameraMatrix2D is simpler
    assert "and $K^{-1}$ is upper triangular, $B$ is\npositive definite" not in prose
    # the image of the absolute conic: the rays through the two vanishing points are (nearly) perpendicular
    assert abs(_num(r"angle between the rays K\^-1 h1 and K\^-1 h2: ([0-9.]+) deg", text, "angle") - 90) < 3
    # degenerate view sets: ranks as the why strings say
    ranks = dict(re.findall(r"^(tilted|parallel|fronto)\s*: rank of V = ([0-9])", text, re.MULTILINE))
    assert ranks == {"tilted": "5", "parallel": "2", "fronto": "2"}
    assert "facing the camera, the equations involve only B11, B12, B22" in text
    # one configuration, one number: 10 views tilted 20-45 deg in both tables
    n10 = re.search(r"^\s+10\s+(\S+)$", text, re.MULTILINE).group(1)
    t2045 = re.search(r"^\s+20-45 deg\s+(\S+)$", text, re.MULTILINE).group(1)
    assert n10 == t2045
    # the quality verdict is reconciled with the error, and the advice with the map's labels
    assert "The verdict is about uncertainty, not error." in prose and "(board units)" not in text
    assert "once 40 views are collected" in prose
    assert "each board shows a coherent swirl" not in prose
    assert ("per-view RMS error reaches several pixels, while the full\ncalibration stays far below a pixel "
            "on every view") in prose
    worst_cf = float(re.search(r"closed form: worst view ([0-9.]+) px RMS", text).group(1))
    worst_full = float(re.search(r"full calibration: worst view ([0-9.]+) px RMS", text).group(1))
    assert worst_cf > 3.0 and worst_full < 0.5
    assert "np.float64(" not in text


def _claims_04(nb) -> None:
    prose, text, code = _prose(nb), _text(nb), _code(nb)
    assert "about 100° across" not in prose
    fov_h = _num(r"field of view through the lens: ([0-9]+) deg horizontally", text, "field of view")
    assert fov_h > 100
    # the corner shift: rho at the image corner, computed here from the printed K and dist
    K = [[307.74, 0, 329.69], [0, 314.98, 244.46]]
    k1, k2 = -0.25659, 0.04481
    x, y = (0 - K[0][2]) / K[0][0], (0 - K[1][2]) / K[1][1]
    r2 = x * x + y * y
    rho = 1 + k1 * r2 + k2 * r2 * r2
    assert f"r^2 = x^2 + y^2 is about {r2:.2f}" in code and f"is about {rho:.2f}" in code
    assert f"pulled {100 * (1 - rho):.0f} % of the way" in code
    assert abs(_num(r"the lens moves an image corner by ([0-9]+) px", text, "corner shift")
               - (1 - rho) * math.hypot(K[0][2], K[1][2])) < 10
    assert "That is the size of the error a pinhole-only calibration makes" not in prose
    # more rounds help only slowly: not all four corners even after 200
    counts = {int(a): int(b) for a, b in re.findall(r"fixed point,\s+([0-9]+) rounds: ([0-4]) of 4", text)}
    assert counts[5] <= counts[200] < 4 and "do not fix the far corners" not in prose
    # alpha = 0 is not a zoom-in: its focal length is shorter than K's
    assert "zoom in until" not in prose
    new_fx = _num(r"alpha = 0: new fx ([0-9.]+) px against K's fx", text, "alpha 0 fx")
    assert new_fx < _num(r"against K's fx ([0-9.]+) px", text, "K's fx") and "the answer is 'smaller'" in text
    # the sliders' numbers: the calibrated lens straightens the lines
    bends = dict(re.findall(r"^(no correction|your guess|the calibrated lens)\s.*up to\s+([0-9.]+) px", text,
                            re.MULTILINE))
    assert float(bends["the calibrated lens"]) < 0.01 < 5 < float(bends["no correction"])
    assert "lens explorer: sliders for k1 and k2" in text


def _claims_05(nb) -> None:
    prose, text, code = _prose(nb), _text(nb), _code(nb)
    assert "earns its keep" not in prose
    n = _num(r"normalized\s+DLT: error against the true H at the 35 corners: mean ([0-9.]+) mm", text, "normalized")
    u = _num(r"unnormalized DLT: error against the true H at the 35 corners: mean ([0-9.]+) mm", text, "unnorm")
    assert "an unnormalized DLT does about as well" in prose and u <= 2 * n + 0.05
    assert "run **parallel** to the board's rows and columns" in prose
    # errors: about a millimetre even at 0.8 m (the table's last row), a pixel's footprint printed
    assert "the error stays around a\n  millimetre even at 0.8 m" in prose
    far_max = float(re.search(r"0.50-0.80 m\s+[0-9.]+mm\s+([0-9.]+)mm", text).group(1))
    assert far_max < 2.0
    near = _num(r"at 0.2 m ahead one rectified pixel row spans ([0-9.]+) mm", text, "footprint")
    far = _num(r"at 0.5 m ahead one rectified pixel row spans ([0-9.]+) mm", text, "footprint")
    assert far > 3 * near
    assert "beyond about half a metre is correspondingly rough" not in prose
    # lane markings: nearly parallel through the rectified frame, splayed through the raw one
    assert "the two lines agree within a few\ndegrees" in prose and "splay them by tens of degrees" in prose
    rect = _num(r"rectified frame: .* they differ by ([0-9.]+) deg", text, "lane angle (rectified)")
    raw = _num(r"raw frame \(wrong: not rectified\): .* they differ by ([0-9.]+) deg", text, "lane angle (raw)")
    assert rect < 6.0 and raw > 20.0
    # height and pitch: recovered = built, Duckietown's default near 10 cm; the yaw's cost as the why says
    h = _num(r"this robot \(your H\):\s+camera ([0-9.]+) cm", text, "height")
    p = _num(r"this robot \(your H\):.* cm above the ground, ([0-9.]+) deg", text, "pitch")
    bh = _num(r"built with: camera ([0-9.]+) cm", text, "built height")
    bp = _num(r"built with: camera [0-9.]+ cm above the ground, ([0-9.]+) deg", text, "built pitch")
    assert abs(h - bh) < 0.5 and abs(p - bp) < 1.0
    assert "about 10 cm above the ground" in prose
    assert abs(_num(r"Duckietown's default homography: camera ([0-9.]+) cm", text, "default height") - 10) < 1
    yaw = _num(r"misplaces a marking 0.5 m ahead by ([0-9.]+) mm", text, "yaw cost")
    assert abs(yaw - 500 * math.sin(math.radians(2))) < 0.05
    assert f"500 mm x sin(2 deg) = {500 * math.sin(math.radians(2)):.0f} mm" in code


CLAIMS = {NB01: _claims_01, NB02: _claims_02, NB03: _claims_03, NB04: _claims_04, NB05: _claims_05}


@pytest.mark.parametrize("name", sorted(CLAIMS))
def test_prose_matches_stored_solution_outputs(name):
    CLAIMS[name](nbformat.read(str(SOLUTIONS / name), as_version=4))


@pytest.mark.slow
@pytest.mark.parametrize("name", sorted(CLAIMS))
def test_prose_matches_what_a_student_sees_first(name, notebook_runs):
    nb, _ = execute_student_once(name.removesuffix(".ipynb"), notebook_runs)  # the run test_notebooks checks
    text = _text(nb)
    assert "!! -> using" in text  # the stand-in path really ran (a banner said so)
    CLAIMS[name](nb)
