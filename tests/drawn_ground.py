"""Frames of a pattern lying on the ground, drawn with numpy through a real camera's intrinsics: the test's
own picture of a scene, independent of the kit's renderer (``dtscal_lib.synth``).

Each pixel (supersampled) is undistorted with OpenCV, its ray met with the ground plane through
``ground_from_ray`` (a 3x3 map from normalized camera rays to homogeneous ground points), and the ground
point coloured by ``paint(gx, gy)`` (grey levels); pixels whose ray does not meet the ground ahead are the
background. A little seeded sensor noise is added, as a camera has.
"""

from __future__ import annotations

import cv2
import numpy as np

BACKGROUND = 100.0


def draw_ground(K, D, size, ground_from_ray, paint, *, scale: int = 2, supersample: int = 2,
                seed: int = 24) -> np.ndarray:
    """The raw (distorted) grey frame of ``size`` = (w, h) times ``scale`` of the painted ground."""
    w, h = size
    Ks = np.asarray(K, dtype=np.float64) * scale
    Ks[2, 2] = 1.0
    W, H, s = w * scale, h * scale, supersample
    v, u = np.mgrid[0:H * s, 0:W * s]
    pix = np.column_stack([(u.ravel() + 0.5) / s - 0.5, (v.ravel() + 0.5) / s - 0.5]).astype(np.float64)
    rays = cv2.undistortPoints(pix.reshape(-1, 1, 2), Ks, np.asarray(D, dtype=np.float64)).reshape(-1, 2)
    g = np.column_stack([rays, np.ones(len(rays))]) @ np.asarray(ground_from_ray, dtype=np.float64).T
    front = g[:, 2] > 0  # the ray meets the ground ahead of the camera
    with np.errstate(divide="ignore", invalid="ignore"):
        grey = paint(g[:, 0] / g[:, 2], g[:, 1] / g[:, 2])
    grey = np.where(front, grey, BACKGROUND).reshape(H, s, W, s).mean(axis=(1, 3))
    grey += np.random.default_rng(seed).normal(0.0, 2.0, grey.shape)
    return np.clip(np.rint(grey), 0, 255).astype(np.uint8)
