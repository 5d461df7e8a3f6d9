"""Hidden grading cases of the dtscal course (instructor only; never handed out).

`dtscal grade` reads this file. `dtscal handout` / `dtscal release` leave the whole
`grading/` folder out, and a test scans the hand-out for these seeds.

Each check: `name` (shown to the student), `weight` (points), `seed` (inputs are drawn
from it), `judge` (close | unchanged | dtype | raises | scaled | truth_H | truth_K | truth_pose |
precision) and the input parameters of its function (see dtscal_lib/grading/checks.py). The
weights of a function sum to 10 or 12.5 (scaled to 10 points: the per-check points then have two
decimals at most, as Gradescope shows them). Each
kind is a dataclass (dtscal_lib/grading/specs.py): a key it does not know is an error naming it.
`h33` scales the input homographies so that H[2, 2] = h33 (code dividing H in place shows);
"random scale and sign" checks alternate the sign, first case negative (never left to the seed);
`precision` runs the mistake catalogue's exact probes (dtscal_lib/mistakes.py), as the self-check
does. Change the seeds each term: the answers are recomputed from the solution notebooks.
"""

POINTS_PER_FUNCTION = 10

CHECKS = {
    "project_points": [
        dict(name="noise-free pixels, skewed camera, 5 poses", weight=3, seed=640173, views=5, n=30,
             camera="skewed", atol=1e-6, rtol=0.0),
        dict(name="pixel coordinates in the thousands (a 4K camera)", weight=2, seed=640179, views=3, n=30,
             camera="4k", atol=1e-5, rtol=0.0),
        dict(name="points far away (20-60 m)", weight=1, seed=640181, views=2, n=10, depth=(20.0, 60.0),
             camera="duckie", atol=1e-6, rtol=0.0),
        dict(name="a single point (N = 1)", weight=1, seed=640187, views=2, n=1, atol=1e-6, rtol=0.0),
        dict(name="returns float64 (N, 2)", weight=1, seed=640189, views=1, n=13, judge="dtype"),
        dict(name="inputs not modified", weight=1, seed=640193, views=1, n=9, judge="unchanged"),
        dict(name="computed in float64 (the precision contract)", weight=1, judge="precision"),
    ],
    "apply_homography": [
        dict(name="board homographies at random scale and sign", weight=4, seed=640211, views=4, n=25,
             random_scale=True, atol=1e-9, rtol=1e-9),
        dict(name="pixel coordinates in the thousands", weight=2, seed=640223, views=2, n=20, camera="4k",
             atol=0.0, rtol=1e-9),
        dict(name="a single point (N = 1)", weight=1, seed=640229, views=2, n=1, atol=1e-9, rtol=1e-9),
        dict(name="returns float64 (N, 2)", weight=1, seed=640231, views=1, n=6, judge="dtype"),
        dict(name="inputs not modified (H[2, 2] != 1)", weight=1, seed=640237, views=1, n=8, h33=-2.5,
             judge="unchanged"),
        dict(name="computed in float64 (the precision contract)", weight=1, judge="precision"),
    ],
    "estimate_homography": [
        dict(name="4 exact correspondences (minimal input)", weight=2, seed=640247, views=3, n=4,
             atol=0.0, rtol=1e-6),
        dict(name="noise-free correspondences", weight=2, seed=640249, views=3, n=30, atol=0.0, rtol=1e-7),
        # noisy checks: judged against the TRUE H with the tolerance derived in grading/tolerances.json
        # (python -m dtscal_lib.grading.tolerances --write; numbers in the comments)
        dict(name="noisy pixels (0.7 px): close to the true homography", weight=2,
             # 0.839 px RMS from the true H (max 0.671 over 10000 draws x 5 formulations, x1.25)
             seed=640253, views=3, n=40, sigma=0.7, judge="truth_H"),
        dict(name="conditioning: noisy coordinates near 20000", weight=2, seed=640259, views=2, n=40,
             # 1.2 px (max 0.960 x1.25); the unnormalized DLT: 1.67, 1.45
             sigma=1.0, offset=2.0e4, span=3.0, judge="truth_H"),
        dict(name="H[2, 2] = 1", weight=1, seed=640261, views=1, n=12, judge="scaled"),
        dict(name="inputs not modified", weight=1, seed=640267, views=1, n=10, judge="unchanged"),
        dict(name="returns float64 (3, 3)", weight=1.25, seed=640268, views=1, n=9, judge="dtype"),
        dict(name="computed in float64 (the precision contract)", weight=1.25, judge="precision"),
    ],
    "intrinsic_constraints": [
        dict(name="random homographies", weight=4, seed=640271, views=3, random_H=True, atol=0.0, rtol=1e-10),
        dict(name="board homographies of a skewed camera", weight=3, seed=640277, views=3, atol=0.0,
             rtol=1e-10),
        dict(name="returns float64 (2, 6)", weight=1, seed=640279, views=1, judge="dtype"),
        dict(name="inputs not modified (H[2, 2] != 1)", weight=1, seed=640283, views=1, h33=3.0,
             judge="unchanged"),
        dict(name="computed in float64 (the precision contract)", weight=1, judge="precision"),
    ],
    "intrinsics_from_homographies": [
        dict(name="3 exact views (minimal input), skewed camera", weight=3, seed=640289, views=3, atol=0.0,
             rtol=1e-6),
        dict(name="15 exact views at random scale and sign", weight=2, seed=640291, views=15, random_scale=True,
             atol=0.0, rtol=1e-6),
        dict(name="12 noisy views (0.3 px): close to the true K", weight=2, seed=640297, views=12, sigma=0.3,
             # 55.6 px max |K - K_true| (max 44.4 over 10000 draws x 6 formulations x1.25; median 3.9)
             camera="duckie", judge="truth_K"),
        dict(name="fewer than 3 views must raise ValueError", weight=1, seed=640301, views=2, judge="raises"),
        dict(name="a single view must raise ValueError", weight=1, seed=640302, views=1, judge="raises"),
        dict(name="returns float64 (3, 3)", weight=1, seed=640303, views=4, judge="dtype"),
        dict(name="the list of homographies not modified (H[2, 2] != 1)", weight=1.25, seed=640304, views=4,
             h33=-4.0, judge="unchanged"),
        dict(name="computed in float64 (the precision contract)", weight=1.25, judge="precision"),
    ],
    "extrinsics_from_homography": [
        dict(name="exact poses from homographies at random scale and sign", weight=4, seed=640307, views=4,
             random_scale=True, atol=1e-8, rtol=1e-8),
        dict(name="noisy homographies (0.5 px): a proper rotation near the true pose", weight=4,
             # 11.6 deg, 12.5 % of |t| (max 9.25 deg, 9.9 % over 10000 draws x 4 formulations x1.25)
             seed=640319, views=4, sigma=0.5, camera="duckie", judge="truth_pose"),
        dict(name="inputs not modified (H[2, 2] != 1)", weight=2, seed=640321, views=1, h33=-2.0,
             judge="unchanged"),
        dict(name="returns float64 (R (3, 3), t (3,))", weight=1.25, seed=640322, views=1, judge="dtype"),
        dict(name="computed in float64 (the precision contract)", weight=1.25, judge="precision"),
    ],
    "distort_normalized": [
        dict(name="tangential lens", weight=2, seed=640327, n=40, lens="tangential", atol=1e-10, rtol=0.0),
        dict(name="radial lens with k3", weight=3, seed=640333, n=40, lens="radial_k3", atol=1e-10, rtol=0.0),
        dict(name="the Duckiebot lens over the whole image", weight=2, seed=640339, lens="duckiebot",
             region="image", atol=1e-10, rtol=0.0),
        dict(name="returns float64 (N, 2)", weight=1, seed=640343, n=7, judge="dtype"),
        dict(name="inputs not modified", weight=1, seed=640349, n=7, judge="unchanged"),
        dict(name="computed in float64 (the precision contract)", weight=1, judge="precision"),
    ],
    "undistort_normalized": [
        dict(name="mild tangential lens", weight=3, seed=640351, n=40, lens="tangential", radius=0.6,
             atol=1e-8, rtol=0.0),
        dict(name="the Duckiebot lens over the whole image, corners included", weight=4, seed=640357,
             lens="duckiebot", region="image", atol=1e-8, rtol=0.0),
        dict(name="no distortion", weight=1, seed=640363, n=10, lens="none", atol=1e-12, rtol=0.0),
        dict(name="inputs not modified", weight=2, seed=640369, n=10, lens="tangential", radius=0.5,
             judge="unchanged"),
        dict(name="returns float64 (N, 2)", weight=1.25, seed=640370, n=6, lens="tangential", radius=0.5,
             judge="dtype"),
        dict(name="computed in float64 (the precision contract)", weight=1.25, judge="precision"),
    ],
    "rectification_maps": [
        dict(name="the Duckiebot, ROS's new camera matrix (alpha = 0)", weight=3, seed=640373, alpha=0.0,
             atol=0.01, rtol=0.0),
        dict(name="a 352x208 lens with tangential terms, alpha = 0.7", weight=3, seed=640379,
             K=(181.0, 178.0, 170.0, 101.0), lens="tangential", size=(352, 208), alpha=0.7, atol=0.01, rtol=0.0),
        dict(name="no distortion and new_K = K: the identity map", weight=1, seed=640381, lens="none",
             size=(160, 120), K=(150.0, 150.0, 80.0, 60.0), atol=0.01, rtol=0.0),
        dict(name="maps are float32 arrays of shape (height, width)", weight=3, seed=640387, lens="tangential",
             size=(96, 64), K=(90.0, 90.0, 48.0, 32.0), judge="dtype", dtype="float32"),
    ],
    "board_ground_points": [
        dict(name="the Duckietown board in its calibration place", weight=4, seed=640389,
             boards=[(7, 5, 0.031, 0.191, -0.093)], atol=1e-12, rtol=0.0),
        dict(name="other boards (cols and rows differ)", weight=3, seed=640393,
             boards=[(4, 3, 0.05, 0.3, -0.2), (3, 6, 0.02, 0.1, 0.05), (9, 2, 0.025, 0.15, -0.11)],
             atol=1e-12, rtol=0.0),
        dict(name="returns float64 (N, 2)", weight=2, seed=640399, boards=[(5, 4, 0.03, 0.2, -0.06)],
             judge="dtype"),
        dict(name="computed in float64 (the precision contract)", weight=1, judge="precision"),
    ],
    "pixel_to_ground": [
        dict(name="ground homographies", weight=4, seed=640403, views=3, n=25, atol=1e-9, rtol=1e-9),
        dict(name="the same homographies at random scale and sign", weight=2, seed=640409, views=3, n=25,
             random_scale=True, atol=1e-9, rtol=1e-9),
        dict(name="returns float64 (N, 2)", weight=1, seed=640411, views=1, n=5, judge="dtype"),
        dict(name="inputs not modified (H[2, 2] != 1)", weight=2, seed=640417, views=1, n=5, h33=-1.7,
             judge="unchanged"),
        dict(name="computed in float64 (the precision contract)", weight=1, judge="precision"),
    ],
    "camera_height_pitch": [
        # noise-free ground homographies of cameras placed by hand: every accepted formulation (lambda from the
        # first column or the mean of both, nearest rotation or r3 = r1 x r2 as is, pitch from asin(-R[2, 2]) or
        # atan2 of the optical axis) agrees to round-off (tests/grading_corpus_correct), hence atol 1e-6
        dict(name="robot cameras 5-30 cm up, pitched 5-50 deg down", weight=4, seed=640421, views=4,
             atol=1e-6, rtol=0.0),
        dict(name="the same at random scale and sign of H", weight=3, seed=640423, views=4, random_scale=True,
             atol=1e-6, rtol=0.0),
        # a camera pitched up (a negative pitch below the horizon) shows abs() on the pitch
        dict(name="cameras pitched 2-15 deg UP (negative pitch)", weight=1.5, seed=640425, views=3,
             pitch=(-15.0, -2.0), atol=1e-6, rtol=0.0),
        dict(name="returns float64 (2,)", weight=1, seed=640427, views=1, judge="dtype"),
        dict(name="inputs not modified (H[2, 2] != 1)", weight=2, seed=640429, views=1, h33=-3.0,
             judge="unchanged"),
        dict(name="computed in float64 (the precision contract)", weight=1, judge="precision"),
    ],
}
