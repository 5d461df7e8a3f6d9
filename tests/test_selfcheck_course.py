"""Tests of the course self-checks for notebooks 03-05 (dtscal_lib.teaching.selfcheck.zhang/distortion/ground).

Each check must pass on a correct implementation (written here independently of the
solution notebooks: OpenCV or dtscal_lib.camera wrapped, or a different derivation),
fail on the typical mistakes students make, and report "not implemented yet" on a stub.
"""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from dtscal_lib import camera as cam
from dtscal_lib.teaching.selfcheck import FAIL, NOT_IMPLEMENTED, PASS
from dtscal_lib.teaching.selfcheck import zhang as nb03, distortion as nb04, ground as nb05
from selfcheck_refs import (_quiet, cv2_p2g, np_distort, np_maps, np_undistort, p2g_no_divide, p2g_transposed,
                            ref_constraints, ref_intrinsics, ref_p2g, status, stub)


# =========================================================================== nb03 references
def ref_extrinsics(K, H):
    """Via OpenCV: decompose with K^-1, orthonormalise with cv2.Rodrigues round trip."""
    A = np.linalg.solve(K, H)
    lam = 1.0 / np.linalg.norm(A[:, 0])
    if A[2, 2] * lam < 0:
        lam = -lam
    r1, r2, t = lam * A[:, 0], lam * A[:, 1], lam * A[:, 2]
    M = np.column_stack([r1, r2, np.cross(r1, r2)])
    U, _, Vt = np.linalg.svd(M)
    R = U @ np.diag([1, 1, np.linalg.det(U @ Vt)]) @ Vt
    return R, t


# wrong variants --------------------------------------------------------------------------
def constraints_transposed(H):
    return ref_constraints(np.asarray(H).T)


def constraints_swapped_rows(H):
    return ref_constraints(H)[::-1]


def constraints_single_cross_term(H):
    H = np.asarray(H, float)
    h1, h2 = H[:, 0], H[:, 1]

    def v(a, c):  # forgot the symmetric partner of each off-diagonal product
        return np.array([a[0] * c[0], a[0] * c[1], a[1] * c[1], a[2] * c[0], a[2] * c[1], a[2] * c[2]])

    return np.array([v(h1, h2), v(h1, h1) - v(h2, h2)])


def intrinsics_zero_skew(Hs):
    K = ref_intrinsics(Hs)
    K[0, 1] = 0.0
    return K


def intrinsics_no_sign_fix(Hs):
    V = np.vstack([ref_constraints(H) for H in Hs])
    b = np.linalg.svd(V)[2][-1]
    b = -b if b[0] > 0 else b  # force the wrong sign
    B = np.array([[b[0], b[1], b[3]], [b[1], b[2], b[4]], [b[3], b[4], b[5]]])
    L = np.linalg.cholesky(B)  # fails: B is negative definite
    K = np.linalg.inv(L.T)
    return K / K[2, 2]


def intrinsics_transposed_H(Hs):
    return ref_intrinsics([np.asarray(H).T for H in Hs])


def intrinsics_no_view_check(Hs):
    V = np.vstack([ref_constraints(H / np.linalg.norm(H)) for H in Hs])
    b = np.linalg.svd(V)[2][-1]
    B = np.array([[b[0], b[1], b[3]], [b[1], b[2], b[4]], [b[3], b[4], b[5]]])
    B = -B if B[0, 0] < 0 else B
    w, Q = np.linalg.eigh(B)
    B = Q @ np.diag(np.abs(w) + 1e-12) @ Q.T
    K = np.linalg.inv(np.linalg.cholesky(B).T)
    return K / K[2, 2]


def extrinsics_det_minus_one(K, H):
    R, t = ref_extrinsics(K, H)
    R = R.copy()
    R[:, 2] = -R[:, 2]
    return R, t


def extrinsics_behind(K, H):
    A = np.linalg.solve(K, H)
    lam = 1.0 / np.linalg.norm(A[:, 0])  # no sign fix
    r1, r2, t = lam * A[:, 0], lam * A[:, 1], lam * A[:, 2]
    M = np.column_stack([r1, r2, np.cross(r1, r2)])
    U, _, Vt = np.linalg.svd(M)
    return U @ Vt, t


def extrinsics_no_svd(K, H):
    A = np.linalg.solve(K, H)
    lam = 1.0 / np.linalg.norm(A[:, 0])
    if A[2, 2] * lam < 0:
        lam = -lam
    r1, r2, t = lam * A[:, 0], lam * A[:, 1], lam * A[:, 2]
    return np.column_stack([r1, r2, np.cross(r1, r2)]), t


# =========================================================================== nb03 tests
def test_constraints_pass_fail_stub():
    assert status(nb03.check_intrinsic_constraints, ref_constraints) == PASS
    assert status(nb03.check_intrinsic_constraints, stub) == NOT_IMPLEMENTED
    for wrong in (constraints_transposed, constraints_swapped_rows, constraints_single_cross_term):
        assert status(nb03.check_intrinsic_constraints, wrong) == FAIL, wrong.__name__


def test_intrinsics_pass_fail_stub():
    assert status(nb03.check_intrinsics_from_homographies, ref_intrinsics) == PASS
    assert status(nb03.check_intrinsics_from_homographies, stub) == NOT_IMPLEMENTED
    for wrong in (intrinsics_zero_skew, intrinsics_no_sign_fix, intrinsics_transposed_H, intrinsics_no_view_check):
        assert status(nb03.check_intrinsics_from_homographies, wrong) == FAIL, wrong.__name__


def test_intrinsics_report_names_the_too_few_views_case():
    rep = _quiet(nb03.check_intrinsics_from_homographies, intrinsics_no_view_check)
    failed = [r.title for r in rep.results if r.status == FAIL]
    assert failed == ["refuses fewer than 3 views with a ValueError"]
    assert "len(Hs) >= 3" in rep.text()


def test_extrinsics_pass_fail_stub():
    assert status(nb03.check_extrinsics_from_homography, ref_extrinsics) == PASS
    assert status(nb03.check_extrinsics_from_homography, stub) == NOT_IMPLEMENTED
    for wrong in (extrinsics_det_minus_one, extrinsics_behind, extrinsics_no_svd):
        assert status(nb03.check_extrinsics_from_homography, wrong) == FAIL, wrong.__name__


def test_extrinsics_behind_message_says_behind():
    rep = _quiet(nb03.check_extrinsics_from_homography, extrinsics_behind)
    assert "BEHIND" in rep.text()


def test_synthetic_views_are_exact_and_in_front():
    Hs, Rs, ts = nb03.synthetic_views(nb03.K_SKEWED, 5, seed=1)
    obj = nb03.DUCKIETOWN_BOARD.object_points()
    for H, R, t in zip(Hs, Rs, ts):
        assert np.linalg.det(R) == pytest.approx(1.0)
        Xc = obj @ R.T + t
        assert np.all(Xc[:, 2] > 0.2)
        uv = cam.project_points(obj, R, t, nb03.K_SKEWED)
        p = np.column_stack([obj[:, :2], np.ones(len(obj))]) @ H.T
        np.testing.assert_allclose(p[:, :2] / p[:, 2:], uv, atol=1e-9)
        assert np.all((uv > 0) & (uv < [640, 480]))


# =========================================================================== nb04 references
ref_distort, ref_undistort, ref_maps = np_distort, np_undistort, np_maps


def cv2_maps(K, dist, new_K, size):
    # OpenCV's routine computes the exercise: refused by the self-check with the grader's words
    return cv2.initUndistortRectifyMap(K, dist, None, new_K, tuple(size), cv2.CV_32FC1)


def lib_maps(K, dist, new_K, size):
    # the kit's own library holds the exercise too: refused the same way
    return cam.rectification_maps(K, dist, new_K, size)


def distort_wrong_tangential_sign(xy, dist):
    d = np.array(dist, float)
    d[2:4] = -d[2:4]
    return np_distort(xy, d)


def distort_swapped_p(xy, dist):
    d = np.array(dist, float)
    d[[2, 3]] = d[[3, 2]]
    return np_distort(xy, d)


def distort_r_not_squared(xy, dist):
    xy = np.asarray(xy, float)
    k1, k2, p1, p2, k3 = dist
    r = np.hypot(xy[:, 0], xy[:, 1])
    radial = 1 + k1 * r + k2 * r**2 + k3 * r**3
    return xy * radial[:, None]


def undistort_fixed_point(xy_d, dist, n_iter=200):
    xy_d = np.asarray(xy_d, float)
    k1, k2, p1, p2, k3 = dist
    x = xy_d.copy()
    for _ in range(n_iter):
        r2 = (x**2).sum(1)
        rad = 1 + k1 * r2 + k2 * r2**2 + k3 * r2**3
        dx = 2 * p1 * x[:, 0] * x[:, 1] + p2 * (r2 + 2 * x[:, 0] ** 2)
        dy = p1 * (r2 + 2 * x[:, 1] ** 2) + 2 * p2 * x[:, 0] * x[:, 1]
        x = np.column_stack([(xy_d[:, 0] - dx) / rad, (xy_d[:, 1] - dy) / rad])
    return x


def undistort_opencv_default(xy_d, dist):
    pts = np.asarray(xy_d, float).reshape(-1, 1, 2)
    return cv2.undistortPoints(pts, np.eye(3), np.asarray(dist, float)).reshape(-1, 2)


def undistort_returns_distorted(xy_d, dist):  # "forgot to invert": distorts again
    return np_distort(xy_d, dist)


def maps_swapped(K, dist, new_K, size):
    mx, my = np_maps(K, dist, new_K, size)
    return my, mx


def maps_transposed_shape(K, dist, new_K, size):
    mx, my = np_maps(K, dist, new_K, size)
    return np.ascontiguousarray(mx.T), np.ascontiguousarray(my.T)


def maps_ignore_new_K(K, dist, new_K, size):
    return np_maps(K, dist, K, size)


def maps_float64(K, dist, new_K, size):
    return np_maps(K, dist, new_K, size, dtype=np.float64)


def maps_undistort_instead(K, dist, new_K, size):  # inverse direction: undistorts pixel positions
    w, h = size
    u, v = np.meshgrid(np.arange(w, dtype=float), np.arange(h, dtype=float))
    uv = np.column_stack([u.ravel(), v.ravel()])
    out = cv2.undistortPoints(uv.reshape(-1, 1, 2), K, dist, P=new_K).reshape(-1, 2)
    return out[:, 0].reshape(h, w).astype(np.float32), out[:, 1].reshape(h, w).astype(np.float32)


# =========================================================================== nb04 tests
def test_distort_pass_fail_stub():
    assert status(nb04.check_distort_normalized, ref_distort) == PASS
    assert status(nb04.check_distort_normalized, stub) == NOT_IMPLEMENTED
    for wrong in (distort_wrong_tangential_sign, distort_swapped_p, distort_r_not_squared):
        assert status(nb04.check_distort_normalized, wrong) == FAIL, wrong.__name__


def test_distort_wrong_sign_fails_only_tangential_cases():
    rep = _quiet(nb04.check_distort_normalized, distort_wrong_tangential_sign)
    failed = {r.title for r in rep.results if r.status == FAIL}
    assert "tangential terms p1, p2" in failed
    assert "k1 only" not in failed


def test_undistort_pass_fail_stub():
    assert status(nb04.check_undistort_normalized, ref_undistort) == PASS
    assert status(nb04.check_undistort_normalized, stub) == NOT_IMPLEMENTED
    for wrong in (undistort_opencv_default, undistort_returns_distorted):
        assert status(nb04.check_undistort_normalized, wrong) == FAIL, wrong.__name__


def test_fixed_point_fails_only_at_the_corners():
    rep = _quiet(nb04.check_undistort_normalized, undistort_fixed_point)
    failed = [r.title for r in rep.results if r.status == FAIL]
    assert failed == ["inverts the Duckiebot lens at the four image corners"]
    assert "Newton" in rep.text()


def test_maps_pass_fail_stub():
    assert status(nb04.check_rectification_maps, ref_maps) == PASS
    for shortcut, words in ((cv2_maps, "cv2.initUndistortRectifyMap"), (lib_maps, "dtscal_lib.camera")):
        rep = _quiet(nb04.check_rectification_maps, shortcut)
        assert not rep.passed and f"calls {words}" in rep.text() and "academic honesty" in rep.text()
    assert status(nb04.check_rectification_maps, stub) == NOT_IMPLEMENTED
    for wrong in (maps_swapped, maps_transposed_shape, maps_ignore_new_K, maps_float64, maps_undistort_instead):
        assert status(nb04.check_rectification_maps, wrong) == FAIL, wrong.__name__


def test_opencv_distort_matches_library():
    xy = np.random.default_rng(0).uniform(-1, 1, (20, 2))
    np.testing.assert_allclose(nb04.opencv_distort(xy, nb04.DIST_TANGENTIAL),
                               cam.distort_normalized(xy, nb04.DIST_TANGENTIAL), atol=1e-12)


# =========================================================================== nb05
def ref_ground(cols, rows, square, x0, y0):
    k = np.arange(cols * rows)
    return np.column_stack([x0 + (k // cols) * square, y0 + (k % cols) * square])


def ground_rows_cols_swapped(cols, rows, square, x0, y0):
    return ref_ground(rows, cols, square, x0, y0)


def ground_far_first(cols, rows, square, x0, y0):
    return ref_ground(cols, rows, square, x0, y0).reshape(rows, cols, 2)[::-1].reshape(-1, 2)


def ground_x_y_swapped(cols, rows, square, x0, y0):
    return ref_ground(cols, rows, square, x0, y0)[:, ::-1]


def ground_rightward(cols, rows, square, x0, y0):
    k = np.arange(cols * rows)
    return np.column_stack([x0 + (k // cols) * square, y0 - (k % cols) * square])


def p2g_divide_by_h33(H, uv):
    H = np.asarray(H, float)
    return p2g_no_divide(H / H[2, 2], uv)


def test_ground_points_pass_fail_stub():
    assert status(nb05.check_board_ground_points, ref_ground) == PASS
    assert status(nb05.check_board_ground_points, stub) == NOT_IMPLEMENTED
    for wrong in (ground_rows_cols_swapped, ground_far_first, ground_x_y_swapped, ground_rightward):
        assert status(nb05.check_board_ground_points, wrong) == FAIL, wrong.__name__


def test_ground_points_wrong_order_message():
    rep = _quiet(nb05.check_board_ground_points, ground_far_first)
    assert "wrong order" in rep.text()


def p2g_float32(H, uv):
    """Right formula, computed in float32 (an image's dtype carried over): off by ~5e-8 m."""
    uv = np.asarray(uv, np.float32)
    p = np.column_stack([uv, np.ones(len(uv), np.float32)]) @ np.asarray(H, np.float32).T
    return (p[:, :2] / p[:, 2:3]).astype(float)


def p2g_rounded_H(H, uv):
    """Right formula with H rounded to 6 decimals (copied from a printout): off by ~0.3 mm."""
    return ref_p2g(np.round(np.asarray(H, float), 6), uv)


def _case_lines(rep) -> dict[str, bool]:
    """case title -> passed, from the report's text (``ok   title`` / ``FAIL title: ...``)."""
    out = {}
    for line in rep.text().splitlines():
        word, _, rest = line.strip().partition(" ")
        if word in ("ok", "FAIL"):
            out[rest.strip().split(":")[0]] = word == "ok"
    return out


@pytest.mark.parametrize("wrong", [p2g_float32, p2g_rounded_H])
def test_pixel_to_ground_opencv_cases_are_needed(wrong):
    """These wrong answers pass the default-homography sanity case (its 2-3 mm tolerance) and fail only
    because each OpenCV comparison (1e-9 m) is there: removing those cases would let them through."""
    cases = _case_lines(_quiet(nb05.check_pixel_to_ground, wrong))
    sanity = [t for t in cases if t.startswith("Duckietown's default homography")]
    opencv = [t for t in cases if t not in sanity]
    assert len(sanity) == 1 and cases[sanity[0]], cases  # the sanity case alone would pass it
    assert len(opencv) == 2 and not any(cases[t] for t in opencv), cases  # each OpenCV case catches it


def test_pixel_to_ground_pass_fail_stub():
    assert status(nb05.check_pixel_to_ground, ref_p2g) == PASS
    rep = _quiet(nb05.check_pixel_to_ground, cv2_p2g)  # OpenCV's routine computes the exercise: refused
    assert not rep.passed and "calls cv2.perspectiveTransform, which does the exercise for you" in rep.text()
    assert status(nb05.check_pixel_to_ground, stub) == NOT_IMPLEMENTED
    for wrong in (p2g_transposed, p2g_no_divide, p2g_divide_by_h33, p2g_float32, p2g_rounded_H):
        assert status(nb05.check_pixel_to_ground, wrong) == FAIL, wrong.__name__
