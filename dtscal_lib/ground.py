"""Ground homography: extrinsic calibration the Duckietown way, pixel <-> ground, bird's-eye view.

The ground plane is the robot frame's ``z = 0`` plane: origin below the midpoint of the
drive wheels, **x forward, y left**, in metres. A plane seen by a pinhole camera is
related to the (rectified, i.e. undistorted) image by a homography (activity text, eqs. (4)-(6),
read from the image to the plane):

    s [x, y, 1]^T = H [u, v, 1]^T

``H`` (3, 3) maps *rectified* pixels to ground metres, as Duckietown's
``camera_extrinsic/<ROBOT>.yaml`` stores it. A raw (distorted) camera pixel is first
rectified (``undistortPoints`` with ``R`` and ``P``), then mapped with ``H``.

The extrinsic procedure on one image (:func:`extrinsics_from_image`; the headless
:func:`dtscal_lib.pipeline.calibrate_extrinsics` finds that image in a recording) follows
``dts duckiebot calibrate_extrinsics``: one frame of the 7x5-corner, 31 mm board lying flat
in front of the robot (near row of inner corners at x = 0.191 m, centred), resized to width 640,
rectified with the intrinsic calibration, corners detected and ordered from the
near-right corner, ``cv2.findHomography(..., RANSAC)``, and Duckietown's ``H[1][2] > 0``
corruption check.

Notes
-----
A homography maps the whole projective plane: pixels *above the horizon* also get a
ground point (behind the robot, mirrored). :func:`pixel_to_ground` does not refuse
them, as Duckietown's ground projection does not; use pixels of the ground only.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from . import duckietown as dt
from .boards import DUCKIETOWN_BOARD, GROUND_NEAR_ROW_X, Board, ground_points, order_for_ground
from .camera import CameraModel, as_points, rectify_image
from .errors import CalibrationError, DtscalError, Reason
from .detect import detect_board_still, to_gray
from .findings import Finding
from .homography import apply_homography, as_homography, invert_homography
from .limits import GROUND_CAMERA_LIMITS, MIRROR_MIN_CONTRAST
from .profiles import DUCKIEBOT, RobotProfile, profile_for

#: default RANSAC inlier threshold, metres on the ground (Duckietown passes OpenCV's
#: default of 3, which in metres rejects nothing; 1 cm rejects a mis-detected corner)
RANSAC_THRESHOLD_M = 0.01


# --------------------------------------------------------------------------- checks
def _points(a, name: str) -> np.ndarray:
    return as_points(a, 2, name)


def _homography(H, name: str = "H") -> np.ndarray:
    return as_homography(H, name)


# --------------------------------------------------------------------------- estimation
def estimate_ground_homography(pixels, ground, *, method: str | int = "ransac",
                               ransac_threshold: float = RANSAC_THRESHOLD_M) -> np.ndarray:
    """Fit the homography from rectified pixels to ground points (``cv2.findHomography``).

    Parameters
    ----------
    pixels : (N, 2) float64 rectified pixels, N >= 4
    ground : (N, 2) float64 ground points, metres (x forward, y left)
    method : ``"ransac"`` (Duckietown's choice, robust to a bad corner) or ``"lsq"``
        (``0``: least squares on all points, then Levenberg-Marquardt refinement)
    ransac_threshold : RANSAC inlier distance on the ground, metres

    Returns
    -------
    (3, 3) float64 ``H`` with ``H[2, 2] = 1``

    Raises
    ------
    CalibrationError
        Fewer than 4 points, degenerate (collinear) points, or OpenCV finds no homography.

    Examples
    --------
    >>> H = np.array([[0.0, -0.001, 0.3], [-0.001, 0.0, 0.32], [0.0, -0.01, 1.0]])
    >>> px = np.array([[100.0, 300], [500, 300], [100, 450], [500, 450], [300, 380]])
    >>> np.allclose(estimate_ground_homography(px, apply_homography(H, px)), H)
    True
    """
    px = _points(pixels, "pixels")
    gr = _points(ground, "ground points")
    if len(px) != len(gr):
        raise CalibrationError(f"got {len(px)} pixels but {len(gr)} ground points; they must pair up")
    if len(px) < 4:
        raise CalibrationError(f"a homography needs at least 4 point pairs, got {len(px)}")
    if method in ("ransac", cv2.RANSAC):
        if not (np.isfinite(ransac_threshold) and ransac_threshold > 0):
            raise CalibrationError(f"ransac_threshold must be a positive distance in metres, got {ransac_threshold!r}")
        H, mask = cv2.findHomography(px, gr, cv2.RANSAC, float(ransac_threshold))
    elif method in ("lsq", 0):
        H, mask = cv2.findHomography(px, gr, 0)
    else:
        raise CalibrationError(f"method must be 'ransac' or 'lsq', got {method!r}")
    if H is None or not np.all(np.isfinite(H)) or abs(H[2, 2]) < 1e-12:
        raise CalibrationError(
            "no homography fits these points (are they collinear, or all in one spot?); the board's "
            "corners must span an area of the image", reason=Reason.HOMOGRAPHY_FAILED,
        )
    H = H / H[2, 2]
    sv = np.linalg.svd(H, compute_uv=False)
    if sv[-1] / sv[0] < 1e-14:
        raise CalibrationError("the fitted homography is singular: the points are degenerate (collinear)",
                               reason=Reason.HOMOGRAPHY_FAILED)
    return H


# --------------------------------------------------------------------------- mapping
def pixel_to_ground(H, uv_rectified) -> np.ndarray:
    """Rectified pixels (N, 2) -> ground points (N, 2), metres (x forward, y left)."""
    return apply_homography(H, uv_rectified)


def ground_to_pixel(H, xy) -> np.ndarray:
    """Ground points (N, 2), metres -> rectified pixels (N, 2), with ``H^-1``."""
    try:
        Hinv = invert_homography(H)
    except DtscalError as exc:
        raise DtscalError(f"{exc} (recalibrate the extrinsics)") from None
    return apply_homography(Hinv, xy)


def distorted_pixel_to_ground(camera: CameraModel, H, uv) -> np.ndarray:
    """Raw camera pixels (N, 2) -> ground points (N, 2), metres.

    Rectifies the points first (``undistortPoints`` with the camera's ``P``, as
    Duckietown's ground projection does), then applies ``H``.
    """
    if not isinstance(camera, CameraModel):
        raise DtscalError(f"camera must be a CameraModel, got {type(camera).__name__}")
    return pixel_to_ground(H, camera.undistort_pixels(uv, rectified=True))


# --------------------------------------------------------------------------- the procedure
@dataclass
class ExtrinsicResult:
    """Outcome of :func:`extrinsics_from_image`.

    Attributes
    ----------
    H : (3, 3) float64 homography, rectified pixels -> ground metres, ``H[2, 2] = 1``
    corners_rectified : (N, 2) float64 detected corners in the rectified image, ground order
    ground : (N, 2) float64 ground coordinates of those corners, metres
    residual_mm : (N,) float64 ``|H(corner) - ground|`` in millimetres
    rectified : the rectified image (H x W [x 3] uint8) the corners were found in
    image_center_ground : (2,) float64 ground point of the rectified image's centre, metres
    pattern_contrast : :func:`board_pattern_contrast` of the board as ordered on the ground (grey
        levels; negative when the frame is mirrored), None when the board's pattern cannot tell
    upside_down : the camera is mounted rotated by 180 degrees (:func:`is_upside_down`: the board's near
        rows are at the top of the image); ``H`` maps its raw, rotated image, as the robot sees it
    """

    H: np.ndarray
    corners_rectified: np.ndarray
    ground: np.ndarray
    residual_mm: np.ndarray
    rectified: np.ndarray
    image_center_ground: np.ndarray
    pattern_contrast: float | None = None
    upside_down: bool = False

    def to_dict(self) -> dict:
        """Plain-Python summary (no image) for JSON/YAML reports."""
        return {
            "homography": [float(v) for v in self.H.ravel()],
            "n_corners": int(len(self.corners_rectified)),
            "residual_mm_mean": float(np.mean(self.residual_mm)),
            "residual_mm_max": float(np.max(self.residual_mm)),
            "residual_mm": [float(v) for v in self.residual_mm],
            "corners_rectified": self.corners_rectified.tolist(),
            "ground": self.ground.tolist(),
            "image_center_ground": [float(v) for v in self.image_center_ground],
            "pattern_contrast": None if self.pattern_contrast is None else float(self.pattern_contrast),
            "upside_down": bool(self.upside_down),
        }


def _check_image(image) -> np.ndarray:
    if not isinstance(image, np.ndarray) or image.size == 0:
        raise CalibrationError("expected a non-empty image array (H x W or H x W x 3)", reason=Reason.EMPTY)
    if image.ndim not in (2, 3) or (image.ndim == 3 and image.shape[2] not in (1, 3, 4)):
        raise CalibrationError(f"expected a grey or colour image, got an array of shape {image.shape}",
                               reason=Reason.BAD_SHAPE)
    if image.dtype != np.uint8:
        raise CalibrationError(f"expected an 8-bit image (uint8), got {image.dtype}; convert it first",
                               reason=Reason.BAD_DTYPE)
    return image


def resize_to_width(image: np.ndarray, width: int = dt.IMAGE_SIZE[0]) -> np.ndarray:
    """Resize to ``width`` keeping the aspect ratio (Duckietown resizes to 640 wide); no-op if already."""
    h, w = image.shape[:2]
    if w == width:
        return image
    new_h = int(round(h * width / w))
    interp = cv2.INTER_AREA if w > width else cv2.INTER_LINEAR
    return cv2.resize(image, (int(width), new_h), interpolation=interp)


def extrinsics_from_image(image: np.ndarray, camera: CameraModel, board: Board = DUCKIETOWN_BOARD, *,
                         method: str = "ransac", profile: RobotProfile | None = None) -> ExtrinsicResult:
    """Duckietown's extrinsic calibration from one frame of the board lying in front of the robot.

    Steps: resize to the camera's width keeping the aspect ratio (640 for a Duckiebot),
    rectify with the intrinsics (``initUndistortRectifyMap(K, D, I, P)``), detect the
    board's inner corners, order them from the near-right corner
    (:func:`~dtscal_lib.boards.order_for_ground`), pair them with
    :func:`~dtscal_lib.boards.ground_points`, fit ``H`` and reject a corrupt one. ``profile`` (default: the
    one the board implies, :func:`~dtscal_lib.profiles.profile_for`) places the board on the ground and says
    whether Duckietown's ``H[1][2] > 0`` rule applies (the Duckiebot's) and the colours are judged.

    Parameters
    ----------
    image : H x W [x 3] uint8 raw (distorted) camera frame, BGR
    camera : the intrinsic calibration (its ``P`` defines the rectified image)
    board : the board on the ground (default: Duckietown's 7x5, 31 mm)
    method : ``"ransac"`` or ``"lsq"``, see :func:`estimate_ground_homography`

    Returns
    -------
    ExtrinsicResult

    Raises
    ------
    CalibrationError
        No board found, aspect ratio that does not match the camera, or a corrupt
        homography (``H[1][2] > 0``).
    """
    if not isinstance(camera, CameraModel):
        raise CalibrationError(f"camera must be a CameraModel, got {type(camera).__name__}")
    image = _check_image(image)
    profile = profile or profile_for(board)
    cw, ch = camera.size
    frame = resize_to_width(image, cw)
    if frame.shape[:2] != (ch, cw):
        raise CalibrationError(
            f"the frame is {image.shape[1]}x{image.shape[0]}, which resized to width {cw} is "
            f"{frame.shape[1]}x{frame.shape[0]}, but the camera was calibrated at {cw}x{ch}; "
            "use frames from the calibrated camera mode", reason=Reason.SIZE_MISMATCH,
        )
    rectified = rectify_image(frame, camera.rectification_maps())
    # one still frame, so the thorough detector is affordable: on the rectified floor view the far
    # squares are only about 12 px tall
    det = detect_board_still(rectified, board, border_margin=dt.BORDER_MARGIN_PX)
    if det.reason == Reason.INCONSISTENT_GRID:
        raise CalibrationError(
            f"the board ({board.describe()}) was found in the rectified image but rejected: {det.detail}. "
            "A smoothly curled print passes this check; a corner that jumps off its neighbours' grid is "
            "mis-detected (glare, a crease, a shadow or clutter on that corner): flatten the board, "
            "light it evenly and take another frame", reason=Reason.INCONSISTENT_GRID,
        )
    if det.reason == Reason.AT_BORDER:
        raise CalibrationError(
            f"the board ({board.describe()}) was found but some corners are within {dt.BORDER_MARGIN_PX} px "
            "of the rectified image's edge; place the robot on the board as instructed, centred, so that "
            "the whole board is well inside the view", reason=Reason.AT_BORDER,
        )
    if not det.found:
        raise CalibrationError(
            f"the board ({board.describe()}) was not found in the rectified image; place the robot on the "
            "board as instructed (the board flat in front of the robot, fully in view, its long side across "
            f"the view, the near row of inner corners {profile.near_row_x} m ahead of {_origin(profile)}), "
            "with even lighting and no glare", reason=det.reason or Reason.NO_BOARD,
        )
    corners = det.corners
    try:
        ordered = order_for_ground(corners, board)
    except DtscalError as e:
        raise CalibrationError(str(e), reason=Reason.BOARD_ORDER) from e
    upside_down = is_upside_down(ordered, board)
    if upside_down:  # the near rows are the top ones: the grid's ground order turned by 180 degrees
        ordered = ordered[::-1].copy()
    ground = ground_points(board, profile.near_row_x, profile.right_column_y)
    H = estimate_ground_homography(ordered, ground, method=method)
    if profile.corrupt_rule and dt.homography_is_corrupt(H):
        raise CalibrationError(
            f"the fitted homography has H[1][2] = {H[1, 2]:g} > 0, which Duckietown rejects as corrupt "
            "(the board looks mirrored or rotated); place the board as instructed and try again",
            reason=Reason.CORRUPT_HOMOGRAPHY,
        )
    residual_mm = 1000.0 * np.linalg.norm(pixel_to_ground(H, ordered) - ground, axis=1)
    centre = np.array([[(cw - 1) / 2.0, (ch - 1) / 2.0]])
    try:
        centre_ground = pixel_to_ground(H, centre)[0]
    except DtscalError:
        raise CalibrationError("the image centre lies on the horizon of the fitted homography; "
                               "the camera must look down at the ground", reason=Reason.HORIZON) from None
    contrast = board_pattern_contrast(rectified, ordered, board) if profile.colours_known else None
    return ExtrinsicResult(H, ordered, ground, residual_mm, rectified, centre_ground, contrast, upside_down)


#: the far row of corners must look this much wider than the near one before a camera is called upside-down:
#: a camera looking straight down sees both alike (ratio 1); Duckietown's default Duckiebot view has the near row
#: 1.50 times as wide as the far one (the default homography, rows at x = 0.191 and 0.315 m) and the DD24's
#: reference view 1.31 times (its scenario0 homography); 5 % keeps a near-vertical view in image order
UPSIDE_DOWN_MIN_RATIO = 1.05
#: the one line that says it (command line, notebook 06)
UPSIDE_DOWN_SAID = ("the camera is mounted upside down (its image is rotated 180 degrees; the board's near rows are "
                    "at the top): calibrated as it is mounted, its raw images to the ground")


def is_upside_down(ordered, board: Board = DUCKIETOWN_BOARD) -> bool:
    """Is the camera mounted upside down? The perspective tells: near rows of the board look wider.

    ``ordered`` are the rectified corners in ground order as :func:`~dtscal_lib.boards.order_for_ground` puts
    them from their image position (the row at the bottom of the image first). The printed board is the same
    turned by 180 degrees (both its near-right and far-left corner squares are white, ``duckietown.md``), so only
    the perspective can tell a camera mounted upside down: when the row ordered first (nearest, for a camera the
    right way up) looks narrower than the last by :data:`UPSIDE_DOWN_MIN_RATIO`, the top of the image is near.
    """
    g = np.asarray(ordered, dtype=np.float64).reshape(board.rows, board.cols, 2)
    near = np.linalg.norm(g[0, -1] - g[0, 0])
    far = np.linalg.norm(g[-1, -1] - g[-1, 0])
    return bool(far > near * UPSIDE_DOWN_MIN_RATIO)


def _origin(profile: RobotProfile, short: bool = False) -> str:
    """What the robot frame's origin is, in words: a Duckiebot's is the midpoint of its wheel axle."""
    if profile is DUCKIEBOT:
        return "the axle" if short else "the wheel axle"
    return "the robot's origin"


def board_pattern_contrast(image: np.ndarray, ordered, board: Board = DUCKIETOWN_BOARD) -> float | None:
    """Is the board seen from above the right way round? Grey-level contrast of its printed pattern.

    The board's squares between the inner corners, in ground order (:func:`~dtscal_lib.boards.order_for_ground`:
    square ``(r, c)`` is the ``r``-th row away from the robot and the ``c``-th column from its right),
    are light when ``r + c`` is even on Duckietown's printed A3 pattern (the corner square nearest the
    robot on its right is white, ``duckietown.md``, and a checkerboard alternates). Returns the mean grey level of
    the squares that should be light minus that of those that should be dark: large and positive
    for a board seen the right way round, negative for a mirrored frame (a mirror swaps the
    colours of the squares against their ground positions, a rotation of the board by 180 degrees
    does not). ``None`` for boards whose pattern cannot tell a mirror from a rotation (an even
    number of inner corners across or along).

    Parameters
    ----------
    image : the rectified frame (grey or BGR) the corners were found in
    ordered : (N, 2) pixels in ground order
    """
    if board.cols % 2 == 0 or board.rows % 2 == 0:
        return None
    grey = to_gray(image).astype(np.float32)
    g = np.asarray(ordered, dtype=np.float64).reshape(board.rows, board.cols, 2)
    centres = (g[:-1, :-1] + g[:-1, 1:] + g[1:, :-1] + g[1:, 1:]) / 4.0
    grey = cv2.blur(grey, (3, 3))
    pts = centres.reshape(-1, 2).astype(np.float32)
    vals = cv2.remap(grey, pts[:, 0].reshape(-1, 1), pts[:, 1].reshape(-1, 1), cv2.INTER_LINEAR,
                     borderMode=cv2.BORDER_REPLICATE).reshape(board.rows - 1, board.cols - 1)
    r, c = np.mgrid[0:board.rows - 1, 0:board.cols - 1]
    light = (r + c) % 2 == 0
    return float(vals[light].mean() - vals[~light].mean())


# --------------------------------------------------------------------------- plausibility
#: what a ground homography must say about the camera that looks at the ground in front of a robot:
#: rows of the one table of belief (:mod:`dtscal_lib.limits`), from Duckietown's real fleet
#: (camera 0.10-0.12 m high, 16-25 degrees down; ground-axis ratios: 95 % under 1.08, at most 1.22)

def camera_pose_from_homography(H, K, near_row_x: float = GROUND_NEAR_ROW_X) -> dict:
    """The camera's pose over the ground, recovered from a ground homography and ``K``.

    ``H`` maps rectified pixels to ground metres, so ``K^-1 H^-1 ~ [r1 r2 t]`` (the seed's
    eq. (13) read backwards): ``r1``, ``r2`` are the ground's x and y axes in the camera
    frame and ``t`` the robot origin. ``K`` (3, 3) is the rectified camera matrix (``P[:, :3]``).

    Returns
    -------
    dict with ``height_m`` (camera centre above the ground), ``position_m`` (x, y of the
    camera centre on the ground), ``pitch_down_deg`` (optical axis below the horizon),
    ``yaw_deg`` (optical axis left of the robot's x axis), ``axis_ratio`` (|r1| / |r2|, 1
    for a true plane view) and ``axis_angle_deg`` (angle between r1 and r2, 90 for one).
    """
    M = np.linalg.solve(np.asarray(K, dtype=np.float64)[:3, :3], np.linalg.inv(_homography(H)))
    lam = 2.0 / (np.linalg.norm(M[:, 0]) + np.linalg.norm(M[:, 1]))
    r1, r2, t = lam * M[:, 0], lam * M[:, 1], lam * M[:, 2]
    if (near_row_x * r1 + t)[2] < 0:  # the board must be in front of the camera
        r1, r2, t = -r1, -r2, -t
    U, _, Wt = np.linalg.svd(np.column_stack([r1, r2, np.cross(r1, r2)]))
    R = U @ Wt
    centre, axis = -R.T @ t, R[2]  # camera centre and optical axis in the robot frame (z up)
    cosang = float(r1 @ r2 / (np.linalg.norm(r1) * np.linalg.norm(r2)))
    return {"height_m": float(centre[2]), "position_m": [float(centre[0]), float(centre[1])],
            "pitch_down_deg": float(np.degrees(np.arcsin(np.clip(-axis[2], -1, 1)))),
            "yaw_deg": float(np.degrees(np.arctan2(axis[1], axis[0]))),
            "axis_ratio": float(np.linalg.norm(r1) / np.linalg.norm(r2)),
            "axis_angle_deg": float(np.degrees(np.arccos(np.clip(cosang, -1, 1))))}


def _turned_board(H, board: Board, profile: RobotProfile) -> np.ndarray:
    """``H`` with the ground turned 180 degrees about the board's centre: the homography of an
    upside-down camera whose corners were ordered by their image position (the fleet's ``H[1][2] > 0``)."""
    xc = float(ground_points(board, profile.near_row_x, profile.right_column_y)[:, 0].mean())
    T = np.array([[-1.0, 0.0, 2.0 * xc], [0.0, -1.0, 0.0], [0.0, 0.0, 1.0]])
    Ht = T @ H
    return Ht / Ht[2, 2]


def ground_homography_doubts(H, K, *, board: Board = DUCKIETOWN_BOARD, pattern_contrast: float | None = None,
                             profile: RobotProfile | None = None, upside_down: bool | None = None) -> list[Finding]:
    """Reasons to disbelieve that ``H`` shows a Duckiebot's camera looking down at the ground ahead.

    The pose of :func:`camera_pose_from_homography` is checked against :data:`GROUND_CAMERA_LIMITS`
    (a Duckiebot's camera height, pitch and heading, from Duckietown's real fleet; a board size
    wrong by a factor of 1.5 or more puts the camera outside the height range), and the board must
    have been seen the right way round (``pattern_contrast`` from :func:`board_pattern_contrast`,
    when known: a mirrored frame gives a homography that looks right but puts the robot's left on
    its right). Each doubt is a :class:`~dtscal_lib.findings.Finding`; an empty list means plausible.

    ``H[1][2] > 0`` is not a doubt by itself: Duckietown refuses to *write* such a homography, but its
    fleet has them, from cameras mounted upside-down (the image rotated 180 degrees, the corners
    ordered by their image position, so the ground comes out turned about the board's centre);
    such a file is judged as that camera, turned back. ``upside_down=True`` says ``H`` is the kit's own fit of an
    upside-down camera (:func:`is_upside_down`), already right: it is judged as it is.

    >>> from dtscal_lib import duckietown as dt
    >>> from dtscal_lib.camera import CameraModel
    >>> cam = CameraModel(dt.default_K(), dt.default_dist(), dt.IMAGE_SIZE)
    >>> ground_homography_doubts(np.reshape(dt.DEFAULT_HOMOGRAPHY, (3, 3)), cam.P[:, :3])
    []
    """
    H = _homography(H)
    profile = profile or profile_for(board)
    lim = GROUND_CAMERA_LIMITS if profile is DUCKIEBOT else profile.ground_limits
    robot = "a Duckiebot's" if profile is DUCKIEBOT else f"the {profile.name.upper()}'s"
    out: list[Finding] = []

    def doubt(code, message, advice):
        out.append(Finding(code, "bad", message, advice))

    rotated = profile.corrupt_rule and not upside_down and dt.homography_is_corrupt(H)
    pose = camera_pose_from_homography(_turned_board(H, board, profile) if rotated else H, K, profile.near_row_x)
    place = ("place the robot on the board as instructed and check --square and --board against the printed "
             "board")
    lo, hi = lim["height_m"]
    if not lo <= pose["height_m"] <= hi:
        factor = pose["height_m"] / ((lo + hi) / 2)
        doubt("camera_height",
              f"the camera would be {pose['height_m']:.3f} m above the ground ({robot} camera: {lo:g}-{hi:g} m)"
              + ((f"; printed squares {factor:.1f} times smaller than --square says would explain it" if factor > 1
                  else f"; printed squares {1 / factor:.1f} times larger than --square says would explain it")
                 if factor > 0 else ""),
              f"check --square against the printed board ({profile.name}: {profile.board.square:g} m; "
              "--robot-type names the robot) and that the intrinsics are this camera's")
    lo, hi = lim["pitch_down_deg"]
    if not lo <= pose["pitch_down_deg"] <= hi:
        doubt("camera_pitch",
              f"the camera would look {pose['pitch_down_deg']:.1f} degrees below the horizon ({robot} "
              f"camera: {lo:g}-{hi:g})", place)
    if abs(pose["yaw_deg"]) > lim["abs_yaw_deg"]:
        doubt("camera_yaw",
              f"the camera would look {pose['yaw_deg']:.0f} degrees to the side of the robot's forward axis "
              f"(at most {lim['abs_yaw_deg']:g})", place)
    if pose["position_m"][0] >= profile.near_row_x:
        doubt("camera_position",
              f"the camera would stand {pose['position_m'][0]:.3f} m ahead of {_origin(profile, short=True)}, on or "
              f"beyond the board (its near row is at {profile.near_row_x} m)", place)
    ratio = max(pose["axis_ratio"], 1 / pose["axis_ratio"])
    if ratio > lim["axis_ratio"] or abs(pose["axis_angle_deg"] - 90) > lim["axis_angle_error_deg"]:
        doubt("not_a_plane_view",
              f"the homography is not a view of a flat ground through this camera (ground axes scaled "
              f"{ratio:.2f}:1 and {pose['axis_angle_deg']:.0f} degrees apart; expected 1:1 and 90)",
              "check the intrinsics (--intrinsics) and that the board was lying flat")
    if pattern_contrast is not None and pattern_contrast < -MIRROR_MIN_CONTRAST:
        doubt("mirrored",
              f"the board is seen mirrored: its squares have the colours of a mirror image (light where the "
              f"printed pattern is dark, contrast {pattern_contrast:.0f} grey levels), so the homography would "
              "put the robot's left on its right",
              "use the camera's own frames, not mirrored ones (a flipped video, a mirrored webcam or a selfie "
              "camera), and Duckietown's printed board")
    return out


# --------------------------------------------------------------------------- views
def _ground_to_view(x_range, y_range, px_per_m) -> tuple[np.ndarray, tuple[int, int]]:
    """Affine map ground metres -> bird's-eye pixel (x forward = up, y left = left), and (w, h)."""
    (x0, x1), (y0, y1) = (tuple(map(float, x_range)), tuple(map(float, y_range)))
    s = float(px_per_m)
    if not (x1 > x0 and y1 > y0 and s > 0):
        raise DtscalError(f"need x_range and y_range as (min, max) with min < max and px_per_m > 0; got "
                          f"{x_range}, {y_range}, {px_per_m}")
    w, h = int(round((y1 - y0) * s)), int(round((x1 - x0) * s))
    if w * h > 25_000_000:
        raise DtscalError(f"the bird's-eye image would be {w}x{h} pixels; lower px_per_m or the ranges")
    # pixel centre (c, r) <-> y = y1 - (c + 0.5)/s, x = x1 - (r + 0.5)/s
    A = np.array([[0.0, -s, y1 * s - 0.5],
                  [-s, 0.0, x1 * s - 0.5],
                  [0.0, 0.0, 1.0]])
    return A, (w, h)


def birdseye_view(rectified_image: np.ndarray, H, *, x_range=(0.1, 0.6), y_range=(-0.25, 0.25),
                  px_per_m: float = 800) -> np.ndarray:
    """Top-down view of the ground seen in a rectified image.

    The output covers ``x_range`` (forward, metres; far at the top) by ``y_range``
    (left positive; left of the robot is the left of the image) at ``px_per_m``;
    pixel ``(c, r)`` shows the ground point ``x = x_max - (r + 0.5)/px_per_m``,
    ``y = y_max - (c + 0.5)/px_per_m``. Ground outside the camera's view is black.

    Returns
    -------
    (round((x_max - x_min) px_per_m), round((y_max - y_min) px_per_m) [, C]) image,
    same dtype as the input.
    """
    if not isinstance(rectified_image, np.ndarray) or rectified_image.size == 0:
        raise DtscalError("expected a non-empty rectified image")
    H = _homography(H)
    A, (w, h) = _ground_to_view(x_range, y_range, px_per_m)
    return cv2.warpPerspective(rectified_image, A @ H, (w, h), flags=cv2.INTER_LINEAR,
                               borderMode=cv2.BORDER_CONSTANT, borderValue=0)


#: the ground grid's colour (BGR): Okabe and Ito's bluish green #009E73, a colour of the kit's palette
#: (:data:`dtscal_lib.figure.PALETTE`; not imported here, which would load matplotlib into every ground user)
GRID_COLOR = (115, 158, 0)


def ground_grid_labels(H, image_size, *, spacing: float = 0.05, x_range=(0.1, 0.6), min_gap_px: float = 12.0):
    """Where :func:`draw_ground_grid` labels its lines of constant x: ``[(text, u, v), ...]``, near to far.

    Each label is the line's distance ahead in cm, at its pixel for ``y = 0``; labels closer than
    ``min_gap_px`` rows to the previous one are left out (they would overlap). ``image_size`` is (width, height).
    """
    H = _homography(H)
    w, h = (int(image_size[0]), int(image_size[1]))
    x0, x1 = map(float, x_range)
    Hinv = np.linalg.inv(H)
    ref = np.sign(H[2] @ np.array([(w - 1) / 2.0, h - 1.0, 1.0]))
    labels, last_v = [], np.inf
    for x in np.arange(np.ceil(x0 / spacing - 1e-9), np.floor(x1 / spacing + 1e-9) + 1) * spacing:
        hom = Hinv @ np.array([x, 0.0, 1.0])
        if np.sign(hom[2]) != ref or abs(hom[2]) < 1e-12:
            continue
        u, v = hom[:2] / hom[2]
        if 0 <= u < w and 0 <= v < h and last_v - v >= min_gap_px:
            last_v = v
            labels.append((f"{x * 100:.0f}", float(u), float(v)))
    return labels


def draw_ground_grid(rectified_image: np.ndarray, H, *, spacing: float = 0.05, x_range=(0.1, 0.6),
                     y_range=(-0.25, 0.25), color=GRID_COLOR, thickness: int = 1,
                     labels: bool = True) -> np.ndarray:
    """Draw ground lines of constant x and constant y (every ``spacing`` metres) on a copy of the image.

    Lines are mapped with ``H^-1``; only the parts in front of the camera are drawn.
    With ``labels`` the constant-x lines are labelled with their distance in cm at
    ``y = 0``. A grey image is converted to BGR so the grid shows in colour.

    Returns
    -------
    H x W x 3 uint8 copy of the image with the grid.
    """
    if not isinstance(rectified_image, np.ndarray) or rectified_image.size == 0:
        raise DtscalError("expected a non-empty rectified image")
    if not (np.isfinite(spacing) and spacing > 0):
        raise DtscalError(f"spacing must be a positive distance in metres, got {spacing!r}")
    H = _homography(H)
    (x0, x1), (y0, y1) = (tuple(map(float, x_range)), tuple(map(float, y_range)))
    if not (x1 > x0 and y1 > y0):
        raise DtscalError(f"x_range and y_range must be (min, max) with min < max, got {x_range}, {y_range}")
    if (x1 - x0) / spacing > 1000 or (y1 - y0) / spacing > 1000:
        raise DtscalError("too many grid lines; increase spacing")
    out = rectified_image.copy()
    if out.ndim == 2 or out.shape[2] == 1:
        out = cv2.cvtColor(out.reshape(out.shape[:2]), cv2.COLOR_GRAY2BGR)
    elif out.shape[2] == 4:
        out = cv2.cvtColor(out, cv2.COLOR_BGRA2BGR)
    h, w = out.shape[:2]
    Hinv = np.linalg.inv(H)
    # the sign of w for ground points in front of the camera: that of a pixel at the image bottom
    ref = np.sign(H[2] @ np.array([(w - 1) / 2.0, h - 1.0, 1.0]))

    def polyline(pts_ground: np.ndarray) -> None:
        hom = pts_ground @ Hinv[:, :2].T + Hinv[:, 2]
        scale = np.abs(pts_ground) @ np.abs(Hinv[2, :2]) + abs(Hinv[2, 2])
        # H^-1 g = p / w' with w' = H[2] . p: in front when its sign matches ref's
        front = np.sign(hom[:, 2]) == ref
        front &= np.abs(hom[:, 2]) > 1e-9 * scale
        px = np.full((len(pts_ground), 2), np.nan)
        px[front] = hom[front, :2] / hom[front, 2:3]
        limit = 4.0 * max(w, h)  # keep coordinates within int range for cv2
        for a, b in zip(px[:-1], px[1:]):
            if np.all(np.isfinite(a)) and np.all(np.isfinite(b)) and np.all(np.abs(np.r_[a, b]) < limit):
                cv2.line(out, (int(round(a[0] * 16)), int(round(a[1] * 16))),
                         (int(round(b[0] * 16)), int(round(b[1] * 16))), color, thickness, cv2.LINE_AA, 4)

    n = 60
    xs = np.arange(np.ceil(x0 / spacing - 1e-9), np.floor(x1 / spacing + 1e-9) + 1) * spacing
    ys = np.arange(np.ceil(y0 / spacing - 1e-9), np.floor(y1 / spacing + 1e-9) + 1) * spacing
    for x in xs:
        polyline(np.column_stack([np.full(n, x), np.linspace(y0, y1, n)]))
    for y in ys:
        polyline(np.column_stack([np.linspace(x0, x1, n), np.full(n, y)]))
    for text, u, v in ground_grid_labels(H, (w, h), spacing=spacing, x_range=x_range) if labels else []:
        cv2.putText(out, text, (int(u) + 3, int(v) - 3), cv2.FONT_HERSHEY_SIMPLEX, 0.35, color, 1, cv2.LINE_AA)
    return out
