"""The course layer (dtscal_lib.teaching.course): the fallback contract, loading student functions, figures' helpers."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from dtscal_lib import camera as cam
from dtscal_lib.teaching.selfcheck import NOT_IMPLEMENTED, PASS
from dtscal_lib.teaching.selfcheck import zhang as nb03, distortion as nb04, ground as nb05
from selfcheck_refs import (_quiet, p2g_no_divide, p2g_transposed, ref_intrinsics, ref_p2g, status,
                                   stub)

# =========================================================================== the notebooks' plumbing
from pathlib import Path  # noqa: E402

import nbformat  # noqa: E402

from dtscal_lib import duckietown as dt  # noqa: E402
from dtscal_lib.teaching import course as fig  # noqa: E402
from dtscal_lib.teaching.release import student_notebook  # noqa: E402

ROOT = Path(__file__).resolve().parent.parent
COURSE = {
    "03_intrinsic_calibration.ipynb": {
        "intrinsic_constraints": nb03.check_intrinsic_constraints,
        "intrinsics_from_homographies": nb03.check_intrinsics_from_homographies,
        "extrinsics_from_homography": nb03.check_extrinsics_from_homography,
    },
    "04_distortion_rectification.ipynb": {
        "distort_normalized": nb04.check_distort_normalized,
        "undistort_normalized": nb04.check_undistort_normalized,
        "rectification_maps": nb04.check_rectification_maps,
    },
    "05_extrinsic_calibration.ipynb": {
        "board_ground_points": nb05.check_board_ground_points,
        "pixel_to_ground": nb05.check_pixel_to_ground,
    },
}


@pytest.mark.parametrize("nb_name", sorted(COURSE))
def test_solution_notebook_functions_pass_and_student_stubs_do_not(nb_name, tmp_path, capsys):
    sol = ROOT / "solutions" / nb_name
    assert sol.exists(), f"{sol} is missing"
    student = tmp_path / nb_name
    nbformat.write(student_notebook(nbformat.read(str(sol), as_version=4), nb_name), str(student))
    for func, check in COURSE[nb_name].items():
        solved = fig.notebook_function(nb_name, func, nb_dir=sol.parent)
        assert solved is not None, capsys.readouterr().out
        assert status(check, solved) == PASS, (func, _quiet(check, solved).text())
        stubbed = fig.notebook_function(nb_name, func, nb_dir=tmp_path)
        assert stubbed is not None
        assert status(check, stubbed) == NOT_IMPLEMENTED, func


def test_exercise_signatures_are_the_graded_ones():
    import inspect

    want = {
        "intrinsic_constraints": ["H"], "intrinsics_from_homographies": ["Hs"],
        "extrinsics_from_homography": ["K", "H"], "distort_normalized": ["xy", "dist"],
        "undistort_normalized": ["xy_d", "dist"], "rectification_maps": ["K", "dist", "new_K", "size"],
        "board_ground_points": ["cols", "rows", "square", "x0", "y0"], "pixel_to_ground": ["H", "uv"],
    }
    for nb_name, funcs in COURSE.items():
        for func in funcs:
            fn = fig.notebook_function(nb_name, func, nb_dir=ROOT / "solutions")
            assert list(inspect.signature(fn).parameters) == want[func], func


def test_notebook_function_reports_unloadable(tmp_path, capsys):
    assert fig.notebook_function("nope.ipynb", "f", nb_dir=tmp_path) is None
    assert "is not in" in capsys.readouterr().out
    nb = nbformat.v4.new_notebook(cells=[nbformat.v4.new_code_cell("import numpy as np"),
                                         nbformat.v4.new_code_cell("def f(:\n    pass")])
    nb.cells[0].metadata["tags"] = ["imports"]
    nb.cells[1].metadata["tags"] = ["exercise"]
    nbformat.write(nb, str(tmp_path / "bad.ipynb"))
    assert fig.notebook_function("bad.ipynb", "f", nb_dir=tmp_path) is None
    assert "SyntaxError" in capsys.readouterr().out


def test_use_or_fallback_stub_uses_fallback_with_message(capsys):
    f = fig.use_or_fallback(stub, ref_p2g, name="pixel_to_ground", check=nb05.check_pixel_to_ground)
    out = capsys.readouterr().out
    assert not f.uses_student and "not implemented yet" in out and "until your function works" in out
    np.testing.assert_allclose(f(dt.default_H(), [[320.0, 479.0]]), ref_p2g(dt.default_H(), [[320.0, 479.0]]))


def test_use_or_fallback_wrong_function_uses_fallback(capsys):
    f = fig.use_or_fallback(p2g_transposed, ref_p2g, check=nb05.check_pixel_to_ground)
    assert not f.uses_student and "does not pass its self-check" in capsys.readouterr().out


def test_use_or_fallback_correct_function_is_used_and_failures_fall_back(capsys):
    f = fig.use_or_fallback(ref_p2g, p2g_no_divide, check=nb05.check_pixel_to_ground)
    assert f.uses_student and f.chosen is ref_p2g
    calls = []

    def flaky(H, uv):
        calls.append(1)
        raise RuntimeError("boom")

    g = fig.use_or_fallback(flaky, ref_p2g)
    capsys.readouterr()
    np.testing.assert_allclose(g(dt.default_H(), [[1.0, 400.0]]), ref_p2g(dt.default_H(), [[1.0, 400.0]]))
    assert calls and "RuntimeError: boom" in capsys.readouterr().out
    h = fig.use_or_fallback(None, ref_p2g, name="estimate_homography")
    assert not h.uses_student and "not available" in capsys.readouterr().out


def test_find_corners_on_a_rendered_board():
    K, d = dt.default_K(), dt.default_dist()
    R = cv2.Rodrigues(np.array([0.3, -0.2, 0.05]))[0]
    t = np.array([-0.09, -0.06, 0.35])
    img = fig.render_board_image(K, d, R, t)
    c = fig.find_corners(img)
    truth = cam.project_points(nb03.DUCKIETOWN_BOARD.object_points(), R, t, K, d)
    assert c is not None
    if np.linalg.norm(c[0] - truth[-1]) < np.linalg.norm(c[0] - truth[0]):
        c = c[::-1]
    assert np.abs(c - truth).max() < 0.5


def test_sample_views_keep_the_board_inside_the_image():
    K = dt.default_K()
    obj = nb03.DUCKIETOWN_BOARD.object_points()
    for R, t in fig.sample_views(K, 8, seed=3, min_tilt_deg=20, max_tilt_deg=45, dist=dt.default_dist()):
        uv = cam.project_points(obj, R, t, K, dt.default_dist())
        assert np.all((uv > 8) & (uv < np.array(dt.IMAGE_SIZE) - 8))
        tilt = np.degrees(np.arccos(R[2, 2]))
        assert 20 - 1e-6 <= tilt <= 45 + 1e-6


def test_degradation_experiment_shows_parallel_views_are_worse():
    text = fig.degradation_experiment(ref_intrinsics, dt.default_K(), view_counts=(10,),
                                      tilts=((0.5, 2.0), (20.0, 45.0)), trials=3)
    rows = [l for l in text.splitlines() if "deg" in l and l.strip()[0].isdigit()]
    vals = [float("inf") if "> 100" in r else float(r.split()[2]) for r in rows]
    assert vals[0] > 10 * vals[1]


def test_ground_error_report_is_zero_for_the_true_homography():
    from dtscal_lib.boards import ground_points
    from dtscal_lib.ground import ground_to_pixel

    H = dt.default_H()
    g = ground_points()
    text = fig.ground_error_report(H, H)
    assert text.count("0.00mm") == 8
    assert np.allclose(fig.ground_error_mm(H, H, ground_to_pixel(H, g)), 0.0)


def test_distort_image_is_undone_by_the_rectification_maps():
    K, d = dt.default_K(), dt.default_dist()
    ideal = cv2.GaussianBlur(fig.grid_image((160, 120), spacing=20, thickness=3), (0, 0), 2.0).astype(float)
    K_small = K.copy()
    K_small[:2] /= 4
    bent = fig.distort_image(ideal.astype(np.float32), K_small, d)
    mx, my = cam.rectification_maps(K_small, d, K_small, (160, 120))
    back = cv2.remap(bent, mx, my, cv2.INTER_LINEAR)
    inner = (slice(15, 105), slice(20, 140))
    err_back = np.mean(np.abs(back[inner] - ideal[inner]))
    err_bent = np.mean(np.abs(bent[inner] - ideal[inner]))
    assert err_back < 3.0 and err_bent > 5 * err_back, (err_back, err_bent)


def test_pinhole_explorer_renders_at_its_shown_size_and_names_the_function(capsys):
    import struct

    from dtscal_lib.teaching.course.projection import EXPLORER_PX

    project = fig.use_or_fallback(stub, lambda K, R, t, X: cam.project_points(X, R, t, K),
                                  fallback_name="the kit's camera.project_points")
    box = fig.pinhole_explorer(project, dt.default_K())
    state = box.explorer
    png = state.image.value
    width, height = struct.unpack(">II", png[16:24])  # the PNG header's IHDR size
    assert (width, height) == EXPLORER_PX
    assert state.image.layout.width == f"{EXPLORER_PX[0]}px"  # shown 1:1, not stretched
    assert "the kit's camera.project_points" in state.status.value  # the stub raised: the stand-in drew it
    # every slider label fits its description box (about 7 px per character at the default font)
    for s in state.sliders.values():
        assert 7 * len(s.description) <= int(s.style.description_width.rstrip("px")), s.description
    state.sliders["distance"].value = 1.0  # redraws without error
    assert state.image.value != png
