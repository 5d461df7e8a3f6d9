"""The reference solutions of all five notebooks against OpenCV on random well-conditioned cases.

The functions come straight from ``solutions/`` via ``release.solution_functions``, so the
solutions, OpenCV and the self-checks are three independent implementations checking each other.
"""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from dtscal_lib.boards import DUCKIETOWN_BOARD
from dtscal_lib.poses import random_board_pose
from dtscal_lib.teaching.release import solution_functions
from nbtools import SOLUTIONS, need

SEEDS = range(12)
BOARD = DUCKIETOWN_BOARD.object_points()


def fns(notebook: str) -> dict:
    return solution_functions(need(SOLUTIONS / f"{notebook}.ipynb"))


def random_K(rng, skew: float = 0.0) -> np.ndarray:
    return np.array([[rng.uniform(280, 420), skew, rng.uniform(300, 340)],
                     [0.0, rng.uniform(280, 420), rng.uniform(220, 260)], [0.0, 0.0, 1.0]])


def random_pose(rng, max_deg: float = 40.0, distance=(0.3, 0.9)):
    return random_board_pose(rng, tilt_deg=(5.0, max_deg), distance=distance)


def cv_transform(H, pts) -> np.ndarray:
    return cv2.perspectiveTransform(np.asarray(pts, float).reshape(-1, 1, 2), np.asarray(H, float)).reshape(-1, 2)


def rms(a, b) -> float:
    return float(np.sqrt(np.mean(np.sum((a - b) ** 2, axis=1))))


# --------------------------------------------------------------------------- 01
@pytest.mark.parametrize("seed", SEEDS)
def test_project_points_matches_cv2(seed):
    project_points = fns("01_pinhole_projection")["project_points"]
    rng = np.random.default_rng(seed)
    K, (R, t) = random_K(rng), random_pose(rng)
    X = BOARD + rng.normal(0, 0.02, BOARD.shape)  # not only planar points
    want = cv2.projectPoints(X, cv2.Rodrigues(R)[0], t, K, None)[0].reshape(-1, 2)
    np.testing.assert_allclose(project_points(K, R, t, X), want, rtol=0, atol=1e-8)


# --------------------------------------------------------------------------- 02
def homography_case(rng, n=35, sigma=0.0):
    K, (R, t) = random_K(rng), random_pose(rng)
    H = K @ np.column_stack([R[:, 0], R[:, 1], t])
    H /= H[2, 2]
    src = rng.uniform([0.0, 0.0], [0.186, 0.124], size=(n, 2))
    dst = cv_transform(H, src) + rng.normal(0, sigma, (n, 2)) * (sigma > 0)
    return H, src, dst


@pytest.mark.parametrize("seed", SEEDS)
def test_homography_noise_free_within_1e8_px(seed):
    f = fns("02_homography")
    H_true, src, dst = homography_case(np.random.default_rng(100 + seed))
    H = f["estimate_homography"](src, dst)
    assert H.shape == (3, 3) and abs(H[2, 2] - 1) < 1e-12
    assert np.abs(cv_transform(H, src) - dst).max() < 1e-8
    np.testing.assert_allclose(H, H_true, rtol=1e-6, atol=1e-9 * np.abs(H_true).max())


@pytest.mark.parametrize("seed", SEEDS)
def test_homography_noisy_within_1_percent_of_findHomography(seed):
    f = fns("02_homography")
    _, src, dst = homography_case(np.random.default_rng(200 + seed), sigma=0.5)
    mine = rms(cv_transform(f["estimate_homography"](src, dst), src), dst)
    ref = rms(cv_transform(cv2.findHomography(src, dst, 0)[0], src), dst)
    assert mine <= 1.01 * ref, (mine, ref)


@pytest.mark.parametrize("seed", SEEDS)
def test_apply_homography_matches_perspectiveTransform(seed):
    apply_homography = fns("02_homography")["apply_homography"]
    H, src, _ = homography_case(np.random.default_rng(300 + seed))
    H = H * np.random.default_rng(seed).uniform(0.1, 10)  # any scale
    np.testing.assert_allclose(apply_homography(H, src), cv_transform(H, src), rtol=0, atol=1e-9)


# --------------------------------------------------------------------------- 03
def views(rng, K, n):
    Hs, poses = [], []
    for _ in range(n):
        R, t = random_pose(rng, max_deg=45)
        H = K @ np.column_stack([R[:, 0], R[:, 1], t])
        Hs.append(H / H[2, 2])
        poses.append((R, t))
    return Hs, poses


def b_of(K) -> np.ndarray:
    B = np.linalg.inv(K).T @ np.linalg.inv(K)
    return np.array([B[0, 0], B[0, 1], B[1, 1], B[0, 2], B[1, 2], B[2, 2]])


@pytest.mark.parametrize("seed", SEEDS)
def test_intrinsic_constraints_vanish_on_the_true_b(seed):
    intrinsic_constraints = fns("03_intrinsic_calibration")["intrinsic_constraints"]
    rng = np.random.default_rng(400 + seed)
    K = random_K(rng, skew=rng.uniform(-5, 5))
    [H], _ = views(rng, K, 1)
    V = np.asarray(intrinsic_constraints(H))
    b = b_of(K)
    assert V.shape == (2, 6)
    assert np.abs(V @ b).max() < 1e-9 * np.abs(V).max() * np.abs(b).max()
    assert np.linalg.matrix_rank(V) == 2


@pytest.mark.parametrize("seed", SEEDS)
def test_intrinsics_from_homographies_within_1e6_relative(seed):
    f = fns("03_intrinsic_calibration")
    rng = np.random.default_rng(500 + seed)
    K = random_K(rng, skew=rng.uniform(-5, 5))
    Hs, _ = views(rng, K, 3 + seed % 4)
    K_est = np.asarray(f["intrinsics_from_homographies"](Hs))
    assert K_est.shape == (3, 3)
    np.testing.assert_allclose(K_est, K, rtol=1e-6, atol=1e-6 * np.abs(K).max())


@pytest.mark.parametrize("seed", SEEDS)
def test_extrinsics_from_homography_recovers_the_pose(seed):
    f = fns("03_intrinsic_calibration")
    rng = np.random.default_rng(600 + seed)
    K = random_K(rng)
    [H], [(R, t)] = views(rng, K, 1)
    R_est, t_est = f["extrinsics_from_homography"](K, H * rng.choice([-1.0, 1.0]) * rng.uniform(0.5, 2))
    R_est, t_est = np.asarray(R_est), np.asarray(t_est).reshape(3)
    np.testing.assert_allclose(R_est @ R_est.T, np.eye(3), atol=1e-9)
    assert np.linalg.det(R_est) == pytest.approx(1.0, abs=1e-9)
    np.testing.assert_allclose(R_est, R, atol=1e-7)
    np.testing.assert_allclose(t_est, t, atol=1e-8)
    ok, rvec, tvec = cv2.solvePnP(BOARD, cv_transform(H, BOARD[:, :2]), K, None, flags=cv2.SOLVEPNP_IPPE)
    np.testing.assert_allclose(t_est, tvec.ravel(), atol=1e-6)


# --------------------------------------------------------------------------- 04
def random_dist(rng) -> np.ndarray:
    return np.array([rng.uniform(-0.3, -0.2), rng.uniform(0.02, 0.06), rng.uniform(-0.005, 0.005),
                     rng.uniform(-0.005, 0.005), rng.uniform(-0.002, 0.002)])


@pytest.mark.parametrize("seed", SEEDS)
def test_distortion_matches_cv2_and_inverts(seed):
    f = fns("04_distortion_rectification")
    rng = np.random.default_rng(700 + seed)
    dist = random_dist(rng)
    xy = rng.uniform([-0.9, -0.7], [0.9, 0.7], size=(50, 2))
    want = cv2.projectPoints(np.column_stack([xy, np.ones(len(xy))]), np.zeros(3), np.zeros(3), np.eye(3),
                             dist)[0].reshape(-1, 2)
    xy_d = np.asarray(f["distort_normalized"](xy, dist))
    np.testing.assert_allclose(xy_d, want, rtol=0, atol=1e-12)
    np.testing.assert_allclose(f["undistort_normalized"](xy_d, dist), xy, rtol=0, atol=1e-9)


@pytest.mark.parametrize("seed", range(4))
def test_rectification_maps_within_001_px_of_opencv(seed):
    rectification_maps = fns("04_distortion_rectification")["rectification_maps"]
    rng = np.random.default_rng(800 + seed)
    K, dist, size = random_K(rng), random_dist(rng), (640, 480)
    new_K = cv2.getOptimalNewCameraMatrix(K, dist, size, float(seed % 2), size)[0]
    mx, my = rectification_maps(K, dist, new_K, size)
    cx, cy = cv2.initUndistortRectifyMap(K, dist, None, new_K, size, cv2.CV_32FC1)
    assert mx.shape == my.shape == (480, 640) and mx.dtype == my.dtype == np.float32
    assert np.abs(mx - cx).max() < 0.01 and np.abs(my - cy).max() < 0.01


# --------------------------------------------------------------------------- 05
@pytest.mark.parametrize("cols, rows, square, x0, y0", [(7, 5, 0.031, 0.191, -0.093), (9, 6, 0.025, 0.15, -0.1)])
def test_board_ground_points_match_the_closed_form(cols, rows, square, x0, y0):
    """Corner k lies at (x0 + (k // cols) * square, y0 + (k % cols) * square), written out here: the exercise
    is never checked against the library's own ground_points."""
    board_ground_points = fns("05_extrinsic_calibration")["board_ground_points"]
    k = np.arange(cols * rows)
    want = np.column_stack([x0 + (k // cols) * square, y0 + (k % cols) * square])
    np.testing.assert_allclose(board_ground_points(cols, rows, square, x0, y0), want, rtol=0, atol=1e-12)


@pytest.mark.parametrize("seed", SEEDS)
def test_pixel_to_ground_matches_perspectiveTransform(seed):
    pixel_to_ground = fns("05_extrinsic_calibration")["pixel_to_ground"]
    rng = np.random.default_rng(900 + seed)
    from dtscal_lib.duckietown import default_H

    H = default_H() * (1 + rng.normal(0, 0.02, (3, 3)))
    uv = rng.uniform([0, 250], [640, 480], size=(40, 2))
    np.testing.assert_allclose(pixel_to_ground(H, uv), cv_transform(H, uv), rtol=1e-12, atol=1e-12)
