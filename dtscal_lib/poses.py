"""Board poses in front of a camera, and the points and homographies they give: the kit's one generator.

Everything that makes synthetic views by construction draws its poses here: the notebooks'
self-checks (:mod:`dtscal_lib.teaching.selfcheck`), the grader's checks (:mod:`dtscal_lib.grading.checks`),
the course figures (:mod:`dtscal_lib.teaching.course`), the benchmarks and the tests. The recorded
session (:mod:`dtscal_lib.synth`) places its hand-held board by pixel and depth instead, but
about the same :attr:`~dtscal_lib.boards.Board.centre`.

Conventions: a pose ``(R, t)`` maps board coordinates to the camera frame, ``Xc = R X + t``
(``R`` (3, 3), ``t`` (3,) in the board's unit, metres for the Duckietown board).

>>> import numpy as np
>>> R, t = random_board_pose(np.random.default_rng(0), distance=0.5)
>>> round(float((R @ DUCKIETOWN_BOARD.centre + t)[2]), 12)  # the board's centre, 0.5 m ahead
0.5
"""

from __future__ import annotations

import cv2
import numpy as np

from .boards import DUCKIETOWN_BOARD, Board
from .camera import pixel_to_normalized
from .errors import DtscalError

__all__ = ["random_board_pose", "look_at_pose", "points_on_rays", "board_homography"]


def random_board_pose(rng: np.random.Generator, board: Board = DUCKIETOWN_BOARD, *,
                      tilt_deg: tuple[float, float] = (5.0, 35.0), distance=(0.3, 0.8),
                      spread: tuple[float, float] = (0.1, 0.08), axis_z: float = 1.0,
                      spin_deg: float | None = None) -> tuple[np.ndarray, np.ndarray]:
    """A random board pose ``(R, t)`` with the board's centre in front of the camera.

    The board is tilted by an angle drawn in ``tilt_deg`` about a random axis (a random
    direction whose z, the optical axis, is scaled by ``axis_z``: below 1 the tilt is mostly
    about axes in the image plane). With ``spin_deg`` the axis is instead drawn in the image
    plane and the board is then also turned about its normal by up to ``+-spin_deg``. Its
    centre lands at depth ``z`` (drawn in ``distance``, or the number itself) and sideways at
    ``(+-spread[0] z, +-spread[1] z)``: within a cone around the optical axis.

    The random draws, in order: the axis (3 normals; or 1 angle), the tilt, (the spin), the
    depth (unless a number), the two sideways offsets. Deterministic for a given ``rng`` state.

    Returns
    -------
    R : (3, 3) float64, board -> camera rotation
    t : (3,) float64, board -> camera translation
    """
    if spin_deg is None:
        axis = rng.normal(size=3)
        axis[2] *= axis_z
        axis /= np.linalg.norm(axis)
        R = cv2.Rodrigues(axis * np.deg2rad(rng.uniform(*tilt_deg)))[0]
    else:
        phi = rng.uniform(0, 2 * np.pi)
        axis = np.array([np.cos(phi), np.sin(phi), 0.0])
        tilt = np.deg2rad(rng.uniform(*tilt_deg))
        spin = np.deg2rad(rng.uniform(-spin_deg, spin_deg))
        R = cv2.Rodrigues(axis * tilt)[0] @ cv2.Rodrigues(np.array([0, 0, spin]))[0]
    z = float(distance) if np.ndim(distance) == 0 else rng.uniform(*distance)
    aim = np.array([rng.uniform(-spread[0], spread[0]) * z, rng.uniform(-spread[1], spread[1]) * z, z])
    return R, aim - R @ board.centre


def look_at_pose(yaw_deg: float = 0.0, pitch_deg: float = 0.0, roll_deg: float = 0.0,
                 distance: float = 0.5, shift_x: float = 0.0, shift_y: float = 0.0,
                 board: Board = DUCKIETOWN_BOARD) -> tuple[np.ndarray, np.ndarray]:
    """A camera looking at the board's centre: world (board) -> camera rotation (3, 3) and translation (3,).

    The camera starts ``distance`` metres in front of the board's centre, looking at it
    straight on, then turns by yaw (about its y axis), pitch (x axis) and roll (z axis),
    and is shifted sideways by ``shift_x``, ``shift_y`` metres in the board plane.

    >>> R, t = look_at_pose(distance=0.5)
    >>> float(t[2]) == 0.5
    True
    """
    if not distance > 0:
        raise DtscalError(f"distance must be positive (metres in front of the board), got {distance}")
    y, p, r = np.deg2rad([yaw_deg, pitch_deg, roll_deg])
    Ry = np.array([[np.cos(y), 0, np.sin(y)], [0, 1, 0], [-np.sin(y), 0, np.cos(y)]])
    Rx = np.array([[1, 0, 0], [0, np.cos(p), -np.sin(p)], [0, np.sin(p), np.cos(p)]])
    Rz = np.array([[np.cos(r), -np.sin(r), 0], [np.sin(r), np.cos(r), 0], [0, 0, 1]])
    R = Rz @ Rx @ Ry
    centre = board.centre + [shift_x, shift_y, 0.0]
    # the camera sits on the board normal through `centre`, at `distance`, then rotates about itself
    t = np.array([0.0, 0.0, distance]) - R @ centre
    return R, t


def points_on_rays(K: np.ndarray, R: np.ndarray, t: np.ndarray, uv, depth) -> np.ndarray:
    """World points (N, 3) that a camera (K, R, t) must see at pixels ``uv`` (N, 2): truth by construction.

    Each pixel is back-projected with ``K^-1`` (skew included) to a ray, the point is put at
    ``depth`` (N,) along the optical axis, and moved to the world frame with ``R^T (Xc - t)``.
    """
    xy = pixel_to_normalized(uv, K)
    Xc = np.column_stack([xy, np.ones(len(xy))]) * np.asarray(depth, dtype=float).reshape(-1, 1)
    return (Xc - np.asarray(t, dtype=float).reshape(1, 3)) @ R  # rows: R^T (Xc - t)


def board_homography(K: np.ndarray, R: np.ndarray, t: np.ndarray) -> np.ndarray:
    """The homography of a board pose, eqs. (5)-(6): ``H = K [r1 r2 t]`` scaled to ``H[2, 2] = 1``.

    Maps board coordinates (X, Y) in metres to pixels, exactly. (3, 3) float64.
    """
    H = np.asarray(K, dtype=float) @ np.column_stack([R[:, 0], R[:, 1], np.reshape(t, 3)])
    return H / H[2, 2]
