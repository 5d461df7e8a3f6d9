"""``dtscal compare``: the projection difference of two calibrations after the aligning rotation (issue 25).

Expectations are computed here, not by dtscal_lib.compare: a camera against itself differs by nothing; two
pinhole cameras that differ only in focal length, principal point at the image centre, differ by
``eps |q - c|`` at pixel ``q`` (the aligning rotation is the identity by symmetry); a principal point moved
by 5 px is mostly a rotation, which the comparison must take out (without it the centre is ~5 px off). The
peer is mrcal 2.2 (Debian's python3-mrcal, ``scripts/install-mrcal.sh``): on two half-set calibrations of
OpenCV's real left photographs the kit's difference must agree with ``mrcal.projection_diff`` within 10 %
(issue 25's acceptance; ``benchmarks/bench_compare.py`` measured 0.03 % at most over 10 splits). Under
``CI=true`` a missing mrcal fails.
"""

from __future__ import annotations

import importlib.util
import json
import sys
from pathlib import Path

import numpy as np
import pytest

from ci import missing
from dtscal_lib import cli
from dtscal_lib.calib_files import IntrinsicCalibration, save_intrinsics
from dtscal_lib.camera import CameraModel, intrinsic_matrix
from dtscal_lib.compare import grid, projection_difference

BENCH = Path(__file__).resolve().parents[1] / "benchmarks" / "bench_compare.py"
SIZE = (640, 480)
CENTRE = ((SIZE[0] - 1) / 2, (SIZE[1] - 1) / 2)


def _pinhole(f, cx=CENTRE[0], cy=CENTRE[1], dist=None, model="plumb_bob"):
    return CameraModel(intrinsic_matrix(f, f, cx, cy), dist, SIZE, model)


def test_a_camera_against_itself_differs_by_nothing():
    cam = _pinhole(300, dist=[-0.25, 0.05, 0.001, -0.001, 0.0])
    c = projection_difference(cam, cam)
    assert c.max_px < 1e-6 and c.rotation_deg < 1e-6  # round-off of the unprojection (Newton to 1e-14)
    assert c.diff.shape == (45, 60)  # mrcal's grid: 60 across, round(480 / 640 * 60) = 45 down


def test_a_focal_length_change_is_eps_times_the_distance_from_the_centre():
    eps = 0.01
    a, b = _pinhole(300), _pinhole(300 * (1 + eps))
    c = projection_difference(a, b)
    # by symmetry about the principal point the best rotation is the identity; then q1 - c = (1 + eps)(q - c)
    want = eps * np.linalg.norm(c.pixels - np.array(CENTRE), axis=-1)
    assert c.rotation_deg < 1e-6
    assert np.allclose(c.diff, want, atol=1e-6)
    assert c.at["top-left"]["diff_px"] == pytest.approx(eps * np.hypot(*CENTRE), abs=1e-6)


def test_a_moved_principal_point_is_mostly_the_aligning_rotation():
    """5 px of cx at f = 300 is a rotation of atan(5/300) ~ 0.95 deg about y; only perspective is left."""
    a, b = _pinhole(300), _pinhole(300, cx=CENTRE[0] + 5)
    c = projection_difference(a, b)
    # within the fit's region (80 px, rays up to 15 deg off-axis) a rotation moves a ray by up to 1/cos^2 = 1.07x
    # its on-axis shift, so the fitted angle lies up to a few per cent below atan(5/300)
    assert c.rotation_deg == pytest.approx(np.degrees(np.arctan(5 / 300)), rel=0.05)
    # near the centre the rotation explains the shift: without it the difference would be 5 px everywhere; with
    # it 0.11 px is left at the grid point nearest the centre (what a rotation cannot do: 1/cos^2 across the fit)
    assert c.at["centre"]["diff_px"] < 0.25
    # at a corner, the rotation of a ray at angle a off-axis moves it by f (tan(a + d) - tan a) - 5 px; a bound:
    # the corner ray is ~53 deg off-axis, where 0.95 deg of rotation moves 300 * d / cos^2(a) = 13.7 px vs 5 px
    assert 1.0 < c.max_px < 15.0


def test_models_of_another_family_compare(tmp_path):
    """rational_polynomial with k4..k6 = 0 is plumb_bob; equidistant with k = 0 differs from the pinhole
    by f (tan(theta) - theta) off-axis, i.e. nothing at the centre and tens of pixels at the corners."""
    d5 = [-0.2, 0.04, 0.0, 0.0, 0.0]
    c = projection_difference(_pinhole(300, dist=d5), _pinhole(300, dist=d5 + [0, 0, 0], model="rational_polynomial"))
    assert c.max_px < 1e-6
    fish = projection_difference(_pinhole(300), _pinhole(300, dist=[0, 0, 0, 0], model="equidistant"))
    r = np.hypot(*CENTRE) / 300
    assert fish.at["centre"]["diff_px"] < 0.05
    assert fish.at["top-left"]["diff_px"] == pytest.approx(300 * (r - np.arctan(r)), rel=0.05)


def _files(tmp_path, a: CameraModel, b: CameraModel) -> tuple[Path, Path]:
    pa = save_intrinsics(IntrinsicCalibration.from_camera(a, "cam"), tmp_path, "a")
    pb = save_intrinsics(IntrinsicCalibration.from_camera(b, "cam"), tmp_path, "b")
    return pa, pb


def test_the_command_prints_json_and_writes_the_figure(tmp_path, capsys):
    pa, pb = _files(tmp_path, _pinhole(300), _pinhole(303))
    assert cli.main(["compare", str(pa), str(pb), "--json", "--report", str(tmp_path / "rep")]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["max_px"] == pytest.approx(0.01 * np.hypot(*CENTRE), rel=1e-6)
    assert set(out["at"]) == {"centre", "top-left", "top-right", "bottom-left", "bottom-right"}
    assert out["within_uncertainty"] is None  # a ROS file carries no uncertainty
    png = Path(out["figure"])
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert cli.main(["compare", str(pa), str(pb)]) == 0
    text = capsys.readouterr().out
    assert f"max {0.01 * np.hypot(*CENTRE):.3f} px" in text and "top-left" in text


def test_the_command_refuses_calibrations_of_different_sizes(tmp_path, capsys):
    other = CameraModel(intrinsic_matrix(300, 300, 160, 120), None, (320, 240))
    pa, pb = _files(tmp_path, _pinhole(300), other)
    assert cli.main(["compare", str(pa), str(pb)]) == 2
    assert "different image sizes" in capsys.readouterr().err


def test_the_cli_offers_every_lens_model_of_the_kit():
    from dtscal_lib.camera import DIST_MODELS

    assert tuple(cli._MODELS) == tuple(DIST_MODELS)


# --------------------------------------------------------------------------- against mrcal
@pytest.fixture(scope="module")
def bench():
    spec = importlib.util.spec_from_file_location("bench_compare", BENCH)
    mod = importlib.util.module_from_spec(spec)
    sys.modules["bench_compare"] = mod
    spec.loader.exec_module(mod)
    problem = mod.mrcal_problem()
    if problem:
        missing(f"mrcal is missing: {problem}")
    return mod


@pytest.mark.parametrize("seed", [None, 0], ids=["even-odd", "random-split-0"])
def test_compare_agrees_with_mrcal_projection_diff(bench, seed):
    obj, img, size = bench.corners("left")
    c = bench.compare_pair(obj, img, size, bench.halves(len(obj), seed))
    assert c["grid_equal"]
    assert {"centre", "max", "rms"} <= set(c["rel"])  # a corner where a half folds over has no value
    assert bench.disagreements(c) == [], c
    assert bench.AGREE_REL == 0.10  # issue 25's acceptance


def test_calibrations_with_their_uncertainty_are_judged_against_it(bench):
    """Two half-set calibrations (the kit's results carry their covariance): the difference is judged against
    sqrt(sigma_A^2 + sigma_B^2); the fit is then mrcal's weighted one over the whole image."""
    from dtscal_lib.calibration import calibrate
    from dtscal_lib.quality import projection_uncertainty, worst_direction_sigma

    obj, img, size = bench.corners("left")
    a_idx, b_idx = bench.halves(len(obj), None)
    ra = calibrate([obj[i] for i in a_idx], [img[i] for i in a_idx], size)
    rb = calibrate([obj[i] for i in b_idx], [img[i] for i in b_idx], size)
    c = projection_difference(ra, rb)
    assert c.focus_radius == float("inf") and c.sigma is not None
    q = np.array([c.at["top-left"]["pixel"]])
    # each calibration's honest covariance (noise model or the views' disagreement, the larger), not the
    # noise model alone: that one is 1.3-2.6x smaller on these photographs and would call the halves different
    def sigma(r):
        cov = (r.normal_blocks(), r.intrinsic_covariance())
        return worst_direction_sigma(projection_uncertainty(r, q, distance=np.inf, cov=cov))

    want = np.hypot(sigma(ra), sigma(rb))[0]
    noise_only = np.hypot(worst_direction_sigma(projection_uncertainty(ra, q, distance=np.inf)),
                          worst_direction_sigma(projection_uncertainty(rb, q, distance=np.inf)))[0]
    assert want > noise_only
    assert c.at["top-left"]["sigma_px"] == pytest.approx(want, rel=1e-9)
    assert c.at["top-left"]["ratio"] == pytest.approx(c.at["top-left"]["diff_px"] / want, rel=1e-9)
    s = c.sentence()
    assert s.startswith(f"differs from the robot's file by at most {c.max_px:.1f} px")
    assert ("within its uncertainty: COMMIT changes little" in s) == (c.max_ratio <= 2.0)


# --------------------------------------------------------------------------- --cross-validate
def test_half_splits_are_seeded_disjoint_halves_of_every_view():
    from dtscal_lib.compare import half_splits

    splits = half_splits(13, 4, seed=3)
    assert splits == half_splits(13, 4, seed=3) and splits != half_splits(13, 4, seed=4)
    for a, b in splits:
        assert sorted(a + b) == list(range(13)) and len(a) == 6 and len(b) == 7
    assert len({tuple(a) for a, _ in splits}) == 4
    with pytest.raises(Exception, match="at least 6"):
        half_splits(5)


def test_cross_validation_ratios_and_finding(bench):
    """Half-set ratios on the real left photographs: each the difference over sqrt(sigma_A^2 + sigma_B^2),
    recomputed here from the comparisons' own grids; a finding only when the median ratio inside exceeds the
    limit (issue 25: mrcal's ratios on these sets are 0.64-1.36 inside, so 2 is not reached; a limit of 0.1
    is)."""
    from dtscal_lib.compare import cross_validate
    from dtscal_lib.limits import CROSS_VALIDATION_RATIO

    obj, img, size = bench.corners("left")
    cv = cross_validate(obj, img, size, splits=3)
    r = cv.ratios()
    assert len(r) == 3 and len(cv.comparisons) == 3
    for c, x in zip(cv.comparisons, r):
        ratio = c.diff / c.sigma
        assert x["corners"] == pytest.approx(np.nanmax(ratio[[0, 0, -1, -1], [0, -1, 0, -1]]), rel=1e-12)
        assert 0 < x["inside"] < 10
    assert CROSS_VALIDATION_RATIO == 2.0 and cv.finding() is None
    f = cv.finding(limit=0.1)
    assert f.code == "cross_validation" and f.severity == "doubtful" and "3 random splits" in f.message


def test_cross_validate_flag_prints_the_splits(tmp_path, capsys):
    real = Path(__file__).resolve().parents[1] / "data" / "real" / "opencv-samples" / "right"
    code = cli.main(["calibrate-intrinsics", "--source", str(real), "--board", "9x6", "--square", "0.03",
                     "--no-write", "-q", "--json", "--cross-validate", "2"])
    assert code == 0
    out = json.loads(capsys.readouterr().out)
    xv = out["cross_validation"]
    assert len(xv["splits"]) == 2 and len(xv["ratios"]) == 2
    assert all(sorted(a + b) == list(range(13)) for a, b in xv["splits"])


# --------------------------------------------------------------------------- notebook 06: after CALIBRATE
@pytest.fixture(scope="module")
def stepped(tmp_path_factory):
    """The live calibrator having seen every frame of the recording (stepped, no thread: deterministic)."""
    from dtscal_lib.datasets import session_dir
    from dtscal_lib.sources import open_source
    from dtscal_lib.ui import LiveCalibrator

    bag = session_dir() / "intrinsics.bag"
    if not bag.exists():
        missing(f"the recorded session {bag} is missing (dtscal synth --out data)")
    app = LiveCalibrator(str(bag), autostart=False, calibration_dir=str(tmp_path_factory.mktemp("calibrations")))
    for f in open_source(bag):
        if f.ok:
            app.loop.step(f)
    yield app
    app.close()


def test_the_live_calibrator_compares_the_new_calibration_with_the_robot_s_file(stepped, tmp_path):
    """On the recording (synthbot, a camera close to Duckietown's factory file): CALIBRATE's results say how far
    the new calibration is from the robot's current file; a robot file 5 % off in focal length is far outside
    the new calibration's uncertainty (5 % of fx at the image corner is ~20 px; its sigma there is ~1 px)."""
    import time

    app = stepped
    app.folder_text.value = str(tmp_path)
    app.set_model("plumb_bob")
    assert app.calibrate(wait=True) is not None
    for _ in range(1200):  # the verdict follows the result in the calibration's thread; a safety net only
        if "dtscal-against" in app.results.value:
            break
        time.sleep(0.1)
    assert "dtscal-against" in app.results.value
    sentence = app.compare_with_robot(str(tmp_path))
    assert sentence.startswith("The new calibration differs from the robot's file (Duckietown's factory "
                               "default.yaml) by at most ")
    assert sentence.endswith("within its uncertainty: COMMIT changes little.")
    # the robot's own file, 5 % off in focal length
    cam = app.result.camera()
    K = cam.K.copy()
    K[0, 0] *= 1.05
    K[1, 1] *= 1.05
    save_intrinsics(IntrinsicCalibration.from_camera(CameraModel(K, cam.dist, cam.size), "synthbot"), tmp_path,
                    app.robot)
    far = app.compare_with_robot(str(tmp_path))
    assert f"camera_intrinsic/{app.robot}.yaml" in far and "COMMIT changes what the robot sees" in far


def test_the_live_calibrator_calibrates_the_lens_model_chosen(stepped):
    """The lens-model choice reaches CALIBRATE: an equidistant calibration of the recording has 4 coefficients
    and the results panel names them."""
    app = stepped
    app.model_choice.value = "equidistant"
    r = app.calibrate(wait=True)
    assert r is not None and r.model == "equidistant" and r.dist.shape == (4,)
    assert "[k1, k2, k3, k4]" in app.results.value
    with pytest.raises(Exception, match="lens model must be one of"):
        app.set_model("fisheye")


# --------------------------------------------------------------------------- σ travels with the file (issue 31)
def _halves_written_by_the_cli(root: Path) -> tuple[Path, Path]:
    """``dtscal calibrate-intrinsics`` on the even and the odd views of OpenCV's real left set (7 and 6 views):
    two files of one camera, each with its uncertainty."""
    real = Path(__file__).resolve().parents[1] / "data" / "real" / "opencv-samples" / "left"
    out = []
    for name, part in (("even", 0), ("odd", 1)):
        src = root / name
        src.mkdir()
        for f in sorted(real.glob("*.jpg"))[part::2]:
            (src / f.name).symlink_to(f)
        assert cli.main(["calibrate-intrinsics", "--source", str(src), "--board", "9x6", "--square", "0.03",
                         "--robot", name, "--out", str(root / "calibrations"), "-q"]) == 0
        out.append(root / "calibrations" / "camera_intrinsic" / f"{name}.yaml")
    return out[0], out[1]


@pytest.fixture(scope="module")
def sigma_files(tmp_path_factory):
    import warnings

    with warnings.catch_warnings():  # a 640x480 camera with fx 532 is no Duckiebot's: named, not an error here
        warnings.simplefilter("ignore")
        return _halves_written_by_the_cli(tmp_path_factory.mktemp("halves"))


def _compare_json(capsys, a, b) -> dict:
    capsys.readouterr()
    assert cli.main(["compare", str(a), str(b), "--json"]) == 0
    return json.loads(capsys.readouterr().out)


def test_two_halves_written_by_the_cli_differ_within_their_uncertainty(sigma_files, capsys):
    """Both files carry their σ; the ROS part of each is what ROS's and Duckietown's readers read (the same
    fields, the extra key after them); compare judges them against sqrt(sigma_A^2 + sigma_B^2): within."""
    import yaml

    from dtscal_lib.calib_files import _dump, load_intrinsics
    from dtscal_lib.file_uncertainty import KEY

    a, b = sigma_files
    for p in (a, b):
        text = p.read_text()
        doc = yaml.safe_load(text)
        assert list(doc)[-1] == KEY and doc[KEY]["parameters"][-3:] == ["rx", "ry", "rz"]
        assert text.startswith(_dump(load_intrinsics(p).to_dict()))  # ROS's layout, then the one extra key
    out = _compare_json(capsys, a, b)
    assert out["uncertainty_unknown"] == [] and out["focus_radius"] == float("inf")
    assert out["within_uncertainty"] is True and 0 < out["max_ratio"] <= 2.0, out
    assert cli.main(["compare", str(a), str(b)]) == 0
    assert "  within their uncertainty: at most" in capsys.readouterr().out


def test_a_calibration_2_percent_off_in_fx_is_not_within(sigma_files, tmp_path, capsys):
    """The odd half with fx + 2 % (its σ kept, restamped at the new values) differs by ~6 px at the corners, far
    beyond its ~2 px sigma; the same edit by hand leaves the file's σ stale: ignored, and compare says why."""
    from dataclasses import replace

    from dtscal_lib import file_uncertainty
    from dtscal_lib.calib_files import load_intrinsics

    a, b = sigma_files
    calib = load_intrinsics(b)
    unc, why = file_uncertainty.load(b)
    assert unc is not None and why == ""
    K = calib.K.copy()
    K[0, 0] *= 1.02
    off = IntrinsicCalibration(calib.camera_name, calib.width, calib.height, K, calib.model, calib.D, calib.R, calib.P)
    restamped = replace(unc, at=file_uncertainty.file_values(off, unc.intrinsics))
    pc = save_intrinsics(off, tmp_path, "off", uncertainty=restamped)
    out = _compare_json(capsys, a, pc)
    assert out["within_uncertainty"] is False and out["max_ratio"] > 2.0, out
    assert cli.main(["compare", str(a), str(pc)]) == 0
    assert "NOT within their uncertainty" in capsys.readouterr().out
    # fx edited by hand after calibration: that file's σ no longer belongs to it
    text = b.read_text()
    fx = repr(float(calib.K[0, 0]))
    edited = tmp_path / "edited.yaml"
    edited.write_text(text.replace(f"data: [{fx},", f"data: [{float(K[0, 0])!r},", 1))
    c = projection_difference(str(a), str(edited))
    assert len(c.unknown) == 1 and "edited after calibration" in c.unknown[0] and "fx" in c.unknown[0]
    assert c.within is False  # judged against a's σ alone, as a new calibration against a robot's file
    # neither file with σ (ROS's own): still compared, not judged, and the sentence says why
    bare = [save_intrinsics(load_intrinsics(p), tmp_path, n) for p, n in ((a, "a"), (b, "b"))]
    c = projection_difference(*map(str, bare))
    assert c.within is None and c.sigma is None and len(c.unknown) == 2
    assert "carries no uncertainty" in c.sentence() and c.max_px > 0


def test_the_file_s_sigma_is_the_calibration_s_and_reads_back_byte_for_byte(bench, tmp_path):
    """The σ propagated from the file equals the one propagated from the calibration with its views (the joint
    covariance of the intrinsics and the rays' rotation is exact at infinity); save -> load -> save gives the
    same bytes; what COMMIT sends to a robot carries no σ."""
    from dtscal_lib import file_uncertainty
    from dtscal_lib.calib_files import load_intrinsics
    from dtscal_lib.calibration import calibrate
    from dtscal_lib.quality import projection_uncertainty, worst_direction_sigma
    from dtscal_lib.robot import _file_content

    obj, img, size = bench.corners("left")
    r = calibrate(obj[::2], img[::2], size, skew=True)
    unc = file_uncertainty.from_result(r)
    assert unc.names[:5] == ("fx", "fy", "cx", "cy", "skew")
    p = save_intrinsics(IntrinsicCalibration.from_camera(r.camera(), "cam"), tmp_path, "r", uncertainty=unc)
    back, why = file_uncertainty.load(p)
    assert why == "" and np.array_equal(back.covariance, unc.covariance)
    q = grid(size, 16).reshape(-1, 2)
    want = worst_direction_sigma(projection_uncertainty(r, q, distance=np.inf,
                                                        cov=(r.normal_blocks(), r.intrinsic_covariance())))
    assert np.allclose(back.projection_sigma(load_intrinsics(p), q), want, rtol=1e-9, atol=0)
    again = save_intrinsics(load_intrinsics(p), tmp_path / "again", "r", uncertainty=back)
    assert again.read_bytes() == p.read_bytes()
    assert file_uncertainty.KEY not in _file_content("camera_intrinsic", "r", p)


def test_compare_of_two_files_with_their_sigma_agrees_with_mrcal(bench, sigma_files):
    """mrcal's projection_diff with uncertainties, the files' σ propagated with mrcal's own gradients
    (benchmarks/mrcal_diff_helper.py): the differences within 10 % (measured 0.014 %), the combined sigma equal
    (measured 1.3e-10), the same judgement."""
    c = bench.compare_files(*sigma_files)
    assert c["grid_equal"] and c["kit_within"] is True
    assert bench.sigma_disagreements(c) == [], c
    assert bench.SIGMA_REL == 1e-6


def test_a_malformed_sigma_block_is_ignored_and_named(sigma_files, tmp_path):
    """A block whose covariance does not fit its parameters, is not symmetric positive definite, or is no mapping:
    the file still loads and compares; its σ is ignored, and the reason names the block."""
    import yaml

    from dtscal_lib import file_uncertainty
    from dtscal_lib.calib_files import _dump, load_intrinsics

    a, b = sigma_files
    doc = yaml.safe_load(b.read_text())
    block = doc[file_uncertainty.KEY]
    n = len(block["parameters"])
    C = np.reshape(block["covariance"]["data"], (n, n))
    bad_cov = C.copy()
    bad_cov[0, 0] = -1.0
    variants = {"short": {**block, "covariance": {**block["covariance"], "data": block["covariance"]["data"][:-1]}},
                "indefinite": {**block, "covariance": {**block["covariance"], "data": bad_cov.ravel().tolist()}},
                "no mapping": "sigma: 2 px"}
    for name, variant in variants.items():
        p = tmp_path / f"{name.replace(' ', '_')}.yaml"
        p.write_text(_dump({**doc, file_uncertainty.KEY: variant}))
        assert load_intrinsics(p) == load_intrinsics(b), name
        unc, why = file_uncertainty.load(p)
        assert unc is None and "block is malformed" in why and file_uncertainty.KEY in why, (name, why)
        c = projection_difference(str(p), str(p))
        assert c.max_px < 1e-6 and len(c.unknown) == 2, name
