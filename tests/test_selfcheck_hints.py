"""Each self-check hint is shown under the check that failed and is about that failure (issue 29).

Each test makes one realistic mistake and reads what the student sees: the hint about that mistake under every
case it failed, no hint about something the student did right, no hint under a case that passed.
"""

from __future__ import annotations

import math

import numpy as np

from selfcheck_refs import np_maps  # the maps written out as a student writes them (the library's are forbidden)
from dtscal_lib.teaching.selfcheck import (check_camera_height_pitch, check_coverage, check_next_board_move,
                                           check_per_view_rms, check_rectification_maps)
from dtscal_lib.teaching.selfcheck import distortion as dist_checks
from dtscal_lib.teaching.selfcheck import ground as ground_checks


def _hints(report) -> list[tuple[str, str]]:
    """(case title, hint shown under it) for every case the student sees a hint under."""
    out, title = [], None
    for line in report.text().splitlines():
        s = line.strip()
        if s.startswith(("ok ", "FAIL ")):
            title = s
        elif s.startswith("hint: "):
            assert title is not None and title.startswith("FAIL"), f"a hint under a passing case: {title}"
            out.append((title, s[len("hint: "):]))
    return out


def _height_pitch(H, K, sign_rule):
    """camera_height_pitch written as in the notebook, with the sign of lambda chosen by ``sign_rule``."""
    G = np.linalg.solve(np.asarray(K, float), np.linalg.inv(np.asarray(H, float)))
    s = 1.0 / np.linalg.norm(G[:, 0])
    if sign_rule(s, G) < 0:
        s = -s
    axes = np.column_stack([s * G[:, 0], s * G[:, 1], s * s * np.cross(G[:, 0], G[:, 1])])
    u, _, vt = np.linalg.svd(axes)
    rot = u @ vt
    centre = -rot.T @ (s * G[:, 2])
    return np.array([centre[2], math.degrees(math.asin(max(-1.0, min(1.0, -rot[2, 2]))))])


def test_the_right_sign_rule_passes():
    assert check_camera_height_pitch(lambda H, K: _height_pitch(H, K, lambda s, G: s * (0.3 * G[2, 0] + G[2, 2])),
                                     ).passed


def test_notebook_03s_sign_rule_gets_the_sign_hint_on_the_cases_it_fails(capsys):
    # t_z > 0 (notebook 03's rule) instead of "a ground point ahead has a positive depth"
    report = check_camera_height_pitch(lambda H, K: _height_pitch(H, K, lambda s, G: s * G[2, 2]))
    hints = _hints(report)
    assert not report.passed and hints
    assert all(h == ground_checks.SIGN_HINT for _t, h in hints), hints
    assert "positive depth" in ground_checks.SIGN_HINT and "t_z > 0" in ground_checks.SIGN_HINT
    failed = [r.title for r in report.results if r.status != "pass"]
    assert len(hints) == len(failed)


def test_a_result_of_the_wrong_shape_gets_the_shape_hint_only(capsys):
    right = lambda H, K: _height_pitch(H, K, lambda s, G: s * (0.3 * G[2, 0] + G[2, 2]))  # noqa: E731
    report = check_camera_height_pitch(lambda H, K: list(right(H, K)) + [0.0])  # [height, pitch, yaw]
    hints = _hints(report)
    assert len(hints) == 3 and all(h == ground_checks.SHAPE_HINT for _t, h in hints), hints


def _maps_reshaped_wrong(K, d, new_K, size):
    mx, my = np_maps(K, d, new_K, size)
    return mx.reshape(size[0], size[1]), my.reshape(size[0], size[1])  # (width, height): rows and columns mixed


def test_maps_of_the_wrong_shape_get_the_shape_hint_and_no_new_k_hint(capsys):
    report = check_rectification_maps(_maps_reshaped_wrong)
    hints = _hints(report)
    assert len(hints) == 4 and all(h == dist_checks.SHAPE_HINT for _t, h in hints), hints
    assert "new_K" not in report.text().split("checks passed", 1)[1].replace("new_K = K", "")


def test_maps_not_a_pair_get_the_pair_hint(capsys):
    report = check_rectification_maps(lambda K, d, nK, size: np.stack(np_maps(K, d, nK, size))[0])
    assert {h for _t, h in _hints(report)} == {dist_checks.PAIR_HINT}


def test_maps_with_the_wrong_values_get_the_cases_own_hints(capsys):
    def off_by_half(K, d, nK, size):  # pixel centres: a realistic value mistake of the right shape and dtype
        mx, my = np_maps(K, d, nK, size)
        return mx + np.float32(0.5), my + np.float32(0.5)

    report = check_rectification_maps(off_by_half)
    hints = [h for _t, h in _hints(report)]
    assert len(hints) == 4 and dist_checks.SHAPE_HINT not in hints and dist_checks.PAIR_HINT not in hints


def test_practice_checks_name_the_mistake(capsys):
    per_coordinate = check_per_view_rms(lambda res: np.array([np.sqrt(np.mean(np.asarray(r) ** 2)) for r in res]))
    assert any("LENGTH of each residual vector" in h for _t, h in _hints(per_coordinate))
    first_not_full = check_next_board_move(lambda bars: {"X": "left", "Y": "up", "Size": "closer", "Skew": "tilt"}[
        next(b.name for b in bars if not b.full)])
    assert any("SMALLEST progress" in h for _t, h in _hints(first_not_full))


def test_coverage_hints_name_the_mistake_made(capsys):
    no_abs = _hints(check_coverage(lambda e, s, k=1.0: float(np.mean(np.asarray(e) <= k * np.asarray(s)))))
    assert no_abs and all("absolute value" in h for _t, h in no_abs), no_abs
    no_k = check_coverage(lambda e, s, k=1.0: float(np.mean(np.abs(e) <= np.asarray(s))))
    assert [h for _t, h in _hints(no_k)] == ["use k: the bound is k * sigma, not sigma"]
