"""Tests of dtscal_lib.calib_files: Duckietown intrinsic/extrinsic YAML read, validate, write."""

from __future__ import annotations

import copy
import math
import os
import stat
import struct
import time
from pathlib import Path

import numpy as np
import pytest
import yaml

from dtscal_lib import calib_files as cf
from dtscal_lib import duckietown as dt
from dtscal_lib.calib_files import (
    IntrinsicCalibration,
    extrinsic_path,
    intrinsic_path,
    load_extrinsics,
    load_intrinsics,
    save_extrinsics,
    save_intrinsics,
    write_defaults,
)
from dtscal_lib.camera import CameraModel
from dtscal_lib.errors import CalibrationFileError, CalibrationFileWarning

from unprivileged import run_unprivileged, shared_tmp


def _bits(values) -> list[bytes]:
    return [struct.pack("<d", float(v)) for v in values]


@pytest.fixture
def calib_dir(tmp_path) -> Path:
    d = tmp_path / "calibrations"
    write_defaults(d)
    return d


def _write_intrinsic_doc(tmp_path, doc, name="bot.yaml") -> Path:
    p = tmp_path / "camera_intrinsic" / name
    p.parent.mkdir(parents=True, exist_ok=True)
    p.write_text(yaml.safe_dump(doc, default_flow_style=None, sort_keys=False))
    return p


def _default_doc() -> dict:
    return copy.deepcopy(dt.DEFAULT_INTRINSICS)


# --------------------------------------------------------------------------- round trips
def test_write_defaults_matches_shipped_text(tmp_path):
    written = write_defaults(tmp_path)
    assert written == [intrinsic_path(tmp_path, "default"), extrinsic_path(tmp_path, "default")]
    text = intrinsic_path(tmp_path, "default").read_text()
    # the layout of the robot's default.yaml: block mappings, flow lists, ints as ints
    assert text.splitlines()[:3] == ["image_width: 640", "image_height: 480",
                                     "camera_name: /porsche911/rosberrypi_cam"]
    assert "  data: [1, 0, 0, 0, 1, 0, 0, 0, 1]" in text
    assert yaml.safe_load(text) == dt.DEFAULT_INTRINSICS
    assert list(yaml.safe_load(text)) == list(dt.DEFAULT_INTRINSICS)
    ext = yaml.safe_load(extrinsic_path(tmp_path, "default").read_text())
    assert ext == {"homography": dt.DEFAULT_HOMOGRAPHY}


def test_write_defaults_never_overwrites(tmp_path):
    write_defaults(tmp_path)
    p = intrinsic_path(tmp_path, "default")
    p.write_text(p.read_text().replace("porsche911", "custom"))
    assert write_defaults(tmp_path) == []
    assert "custom" in p.read_text()


def test_defaults_round_trip_bit_identical(calib_dir):
    c1 = load_intrinsics(intrinsic_path(calib_dir, "default"))
    assert c1.to_dict() == dt.DEFAULT_INTRINSICS
    out = save_intrinsics(c1, calib_dir, "bot")
    assert out == calib_dir / "camera_intrinsic" / "bot.yaml"
    c2 = load_intrinsics(out)
    assert c2 == c1
    for name in "KDRP":
        assert _bits(getattr(c1, name).ravel()) == _bits(getattr(c2, name).ravel())
    raw1 = yaml.safe_load(intrinsic_path(calib_dir, "default").read_text())
    raw2 = yaml.safe_load(out.read_text())
    assert raw1 == raw2 and list(raw1) == list(raw2)
    # ints stay ints where the source had ints
    assert [type(v) for v in raw2["camera_matrix"]["data"]] == [type(v) for v in raw1["camera_matrix"]["data"]]

    H1 = load_extrinsics(extrinsic_path(calib_dir, "default"))
    save_extrinsics(H1, calib_dir, "bot")
    H2 = load_extrinsics(extrinsic_path(calib_dir, "bot"))
    assert _bits(H1.ravel()) == _bits(H2.ravel()) == _bits(dt.DEFAULT_HOMOGRAPHY)


def test_awkward_floats_round_trip_exactly(tmp_path):
    rng = np.random.default_rng(3)
    K = np.array([[316.0 + rng.random() / 3, 1e-17, 320.1 + rng.random()], [0, 318.0 + 1 / 7, 240.5], [0, 0, 1]])
    D = np.array([-0.27 - rng.random() * 1e-9, 1e-300, -0.0, 5e-324, 1.0 / 3])
    P = np.zeros((3, 4))
    P[:, :3] = K * [[0.7], [0.7], [1]]
    P[2, 2] = 1.0
    c = IntrinsicCalibration("/bot/cam", 640, 480, K, "plumb_bob", D, np.eye(3), P)
    c2 = load_intrinsics(save_intrinsics(c, tmp_path, "bot"))
    for name in "KDP":
        assert _bits(getattr(c, name).ravel()) == _bits(getattr(c2, name).ravel())
    assert math.copysign(1, c2.D[2]) == -1  # -0.0 kept


def test_camera_and_from_camera(calib_dir):
    c = load_intrinsics(intrinsic_path(calib_dir, "default"))
    cam = c.camera()
    assert isinstance(cam, CameraModel)
    assert cam.size == (640, 480)
    np.testing.assert_array_equal(cam.P, dt.default_P())
    np.testing.assert_array_equal(cam.K, dt.default_K())
    back = IntrinsicCalibration.from_camera(cam, c.camera_name)
    assert back == c


def test_from_camera_radial2_and_alpha_zero_P():
    cam = CameraModel(dt.default_K(), [-0.25, 0.05], (640, 480), model="radial2")
    c = IntrinsicCalibration.from_camera(cam, "/bot/camera")
    assert c.distortion_model == "plumb_bob"
    np.testing.assert_array_equal(c.D, [-0.25, 0.05, 0, 0, 0])
    np.testing.assert_array_equal(c.R, np.eye(3))
    np.testing.assert_array_equal(c.P, cam.P)


def test_camera_refuses_stereo_rotation():
    R = np.array([[0.0, -1, 0], [1, 0, 0], [0, 0, 1]])
    c = IntrinsicCalibration("/x", 640, 480, dt.default_K(), "plumb_bob", dt.default_dist(), R, dt.default_P())
    with pytest.raises(CalibrationFileError, match="not the identity"):
        c.camera()


# --------------------------------------------------------------------------- malformed input
def test_missing_file(tmp_path):
    with pytest.raises(CalibrationFileError, match=r"nope\.yaml: file not found"):
        load_intrinsics(tmp_path / "nope.yaml")
    with pytest.raises(CalibrationFileError, match="file not found"):
        load_extrinsics(tmp_path / "nope.yaml")


def test_yaml_syntax_error(tmp_path):
    p = tmp_path / "bad.yaml"
    p.write_text("image_width: 640\ncamera_matrix: {rows: 3, cols: [\n")
    with pytest.raises(CalibrationFileError, match=r"bad\.yaml: is not valid YAML at line"):
        load_intrinsics(p)


@pytest.mark.parametrize("text", ["", "- 1\n- 2\n", "just a string\n"])
def test_not_a_mapping(tmp_path, text):
    p = tmp_path / "odd.yaml"
    p.write_text(text)
    with pytest.raises(CalibrationFileError, match=r"odd\.yaml: (is empty|must be a YAML mapping)"):
        load_intrinsics(p)


@pytest.mark.parametrize("loader", [load_intrinsics, load_extrinsics])
def test_hostile_tag_is_not_executed(tmp_path, loader):
    marker = tmp_path / "pwned"
    p = tmp_path / "evil.yaml"
    p.write_text(f'homography: !!python/object/apply:os.system ["touch {marker}"]\n'
                 'image_width: !!python/object/apply:pathlib.Path.touch '
                 f'[!!python/object/apply:pathlib.Path ["{marker}"]]\n')
    with pytest.raises(CalibrationFileError, match=r"evil\.yaml: contains a non-data tag .* was not loaded"):
        loader(p)
    assert not marker.exists()


@pytest.mark.parametrize("text", ["homography: !!python/tuple [1, 2, 3]\n", "homography: !custom [1]\n",
                                  "homography: !!python/name:os.system\n"])
def test_other_tags_refused(tmp_path, text):
    p = tmp_path / "tag.yaml"
    p.write_text(text)
    with pytest.raises(CalibrationFileError, match=r"tag\.yaml: contains a non-data tag \('"):
        load_extrinsics(p)


def test_unhashable_key_is_not_called_a_tag(tmp_path):
    p = tmp_path / "key.yaml"
    p.write_text("? [1]\n: 2\n")
    with pytest.raises(CalibrationFileError, match="not valid calibration YAML: found unhashable key"):
        load_extrinsics(p)


@pytest.mark.parametrize("value", ["!!binary AAAA", "!!set {1}", "2001-12-14", "{a: 1}"])
def test_safe_but_non_numeric_values(tmp_path, value):
    p = tmp_path / "ext.yaml"
    p.write_text(f"homography: [{value}, 0, 0, 0, 1, -1, 0, 0, 1]\n")
    with pytest.raises(CalibrationFileError, match=r"homography\[0\] is .*expected a number"):
        load_extrinsics(p)


@pytest.mark.parametrize("field", cf.INTRINSIC_KEYS)
def test_missing_field(tmp_path, field):
    doc = _default_doc()
    del doc[field]
    p = _write_intrinsic_doc(tmp_path, doc)
    with pytest.raises(CalibrationFileError, match=rf"bot\.yaml: missing field\(s\) {field}"):
        load_intrinsics(p)


@pytest.mark.parametrize("sub", ["rows", "cols", "data"])
def test_missing_matrix_subfield(tmp_path, sub):
    doc = _default_doc()
    del doc["projection_matrix"][sub]
    with pytest.raises(CalibrationFileError, match=f"projection_matrix has no '{sub}'"):
        load_intrinsics(_write_intrinsic_doc(tmp_path, doc))


def test_wrong_data_length_message(tmp_path):
    doc = _default_doc()
    doc["camera_matrix"]["data"] = doc["camera_matrix"]["data"][:8]
    p = _write_intrinsic_doc(tmp_path, doc)
    with pytest.raises(CalibrationFileError) as e:
        load_intrinsics(p)
    assert str(e.value) == f"{p}: camera_matrix.data has 8 values; expected rows*cols = 9"


@pytest.mark.parametrize("key,rows,cols", [("camera_matrix", 3, 4), ("projection_matrix", 4, 3),
                                           ("rectification_matrix", 1, 9)])
def test_wrong_matrix_shape(tmp_path, key, rows, cols):
    doc = _default_doc()
    doc[key]["rows"], doc[key]["cols"] = rows, cols
    with pytest.raises(CalibrationFileError, match=f"{key} is {rows}x{cols}, expected"):
        load_intrinsics(_write_intrinsic_doc(tmp_path, doc))


def test_distortion_needs_five(tmp_path):
    doc = _default_doc()
    doc["distortion_coefficients"] = {"rows": 1, "cols": 4, "data": [-0.2, 0.04, 0, 0]}
    with pytest.raises(CalibrationFileError, match=r"distortion_coefficients has 4 values; plumb_bob needs 5 \[k1"):
        load_intrinsics(_write_intrinsic_doc(tmp_path, doc))


@pytest.mark.parametrize("token", [".nan", ".inf", "-.inf", ".NaN"])
def test_nan_inf(tmp_path, token):
    p = tmp_path / "nan.yaml"
    write_defaults(tmp_path)
    text = intrinsic_path(tmp_path, "default").read_text().replace("314.9827773443905", token)
    p.write_text(text)
    with pytest.raises(CalibrationFileError, match=r"camera_matrix\.data\[4\] is .*finite"):
        load_intrinsics(p)


@pytest.mark.parametrize("value,hint", [("'307.7'", "unquoted"), ("1e-05", "1.0e-05"), ("null", "expected a number"),
                                        ("true", "expected a number"), ("[1, 2]", "expected a number")])
def test_wrong_types_in_data(tmp_path, value, hint):
    write_defaults(tmp_path)
    text = intrinsic_path(tmp_path, "default").read_text().replace("307.7379294605756", value)
    p = tmp_path / "types.yaml"
    p.write_text(text)
    with pytest.raises(CalibrationFileError, match=r"camera_matrix\.data\[0\] is") as e:
        load_intrinsics(p)
    assert hint in str(e.value)


@pytest.mark.parametrize("field,value,pattern", [
    ("image_width", "640", "image_width is '640', expected a positive integer"),
    ("image_width", 640.0, "image_width is 640.0, expected a positive integer"),
    ("image_height", 0, "image_height is 0, expected a positive integer"),
    ("image_height", -480, "image_height is -480"),
    ("camera_name", 7, "camera_name is 7, expected a string"),
    # ROS's other models are read (tests/test_lens_models.py), each with its own number of coefficients
    ("distortion_model", "equidistant", r"equidistant needs 4 \[k1, k2, k3, k4\]"),
    ("distortion_model", "rational_polynomial", r"rational_polynomial needs 8 \[k1, k2, p1, p2, k3, k4, k5, k6\]"),
    ("distortion_model", "pinhole", "expected one of"),
])
def test_wrong_scalar_fields(tmp_path, field, value, pattern):
    doc = _default_doc()
    doc[field] = value
    with pytest.raises(CalibrationFileError, match=pattern):
        load_intrinsics(_write_intrinsic_doc(tmp_path, doc))


def test_rows_as_string(tmp_path):
    doc = _default_doc()
    doc["camera_matrix"]["rows"] = "3"
    with pytest.raises(CalibrationFileError, match="camera_matrix.rows is '3', expected a positive integer"):
        load_intrinsics(_write_intrinsic_doc(tmp_path, doc))


def _k_doc(**changes) -> dict:
    doc = _default_doc()
    data = doc["camera_matrix"]["data"]
    idx = {"fx": 0, "s": 1, "cx": 2, "fy": 4, "cy": 5, "k10": 3, "k22": 8}
    for k, v in changes.items():
        data[idx[k]] = v
    return doc


@pytest.mark.parametrize("changes,pattern", [
    ({"fx": -307.7}, "focal lengths must be positive"),
    ({"fy": 0}, "focal lengths must be positive"),
    ({"fx": 3000.0}, "aspect ratio"),
    ({"cx": 700.0}, "principal point .* outside the 640x480 image"),
    ({"cy": -3.0}, "principal point"),
    ({"s": 60.0}, "skew"),
    ({"k10": 1.0}, r"must look like \[fx, s, cx"),
    ({"k22": 2.0}, r"must look like \[fx, s, cx"),
])
def test_implausible_K(tmp_path, changes, pattern):
    p = _write_intrinsic_doc(tmp_path, _k_doc(**changes))
    with pytest.raises(CalibrationFileError, match=pattern) as e:
        load_intrinsics(p)
    assert str(p) in str(e.value) and "camera_matrix" in str(e.value)


def test_small_skew_accepted(tmp_path):
    c = load_intrinsics(_write_intrinsic_doc(tmp_path, _k_doc(s=0.5)))
    assert c.K[0, 1] == 0.5


def test_R_must_be_rotation(tmp_path):
    doc = _default_doc()
    doc["rectification_matrix"]["data"] = [1, 0, 0, 0, 1, 0, 0, 0, 1.001]
    with pytest.raises(CalibrationFileError, match="rectification_matrix is not a rotation"):
        load_intrinsics(_write_intrinsic_doc(tmp_path, doc))
    doc["rectification_matrix"]["data"] = [1, 0, 0, 0, 1, 0, 0, 0, -1]  # reflection: det -1
    with pytest.raises(CalibrationFileError, match="det = -1"):
        load_intrinsics(_write_intrinsic_doc(tmp_path, doc))
    a = 0.1
    doc["rectification_matrix"]["data"] = [math.cos(a), -math.sin(a), 0, math.sin(a), math.cos(a), 0, 0, 0, 1]
    assert load_intrinsics(_write_intrinsic_doc(tmp_path, doc)).R[0, 1] == -math.sin(a)


@pytest.mark.parametrize("index,value,pattern", [(10, 0.5, r"third row is \[0\.0, 0\.0, 0\.5"),
                                                 (8, 0.1, "expected \\[0, 0, 1, 0\\]"),
                                                 (0, -210.0, "fx' = -210")])
def test_P_form(tmp_path, index, value, pattern):
    doc = _default_doc()
    doc["projection_matrix"]["data"][index] = value
    with pytest.raises(CalibrationFileError, match=pattern):
        load_intrinsics(_write_intrinsic_doc(tmp_path, doc))


def test_P_third_row_translation_is_read_as_duckietown_reads_it(tmp_path):
    """Duckietown's DD24 calibration YAML has P's third row [0, 0, 1, 1]; its loader uses only P's left 3x3."""
    doc = _default_doc()
    doc["projection_matrix"]["data"][11] = 1
    path = _write_intrinsic_doc(tmp_path, doc)
    pattern = r"third row is \[0\.0, 0\.0, 1\.0, 1\.0\].*read as \[0, 0, 1, 0\]"
    with pytest.warns(CalibrationFileWarning, match=pattern) as w:
        calib = load_intrinsics(path)
    assert len(w) == 1 and str(path) in str(w[0].message)
    np.testing.assert_array_equal(calib.P, dt.default_P())
    np.testing.assert_array_equal(calib.K, dt.default_K())


def test_direct_construction_validates():
    with pytest.raises(CalibrationFileError, match="principal point"):
        IntrinsicCalibration("/x", 320, 240, dt.default_K(), "plumb_bob", dt.default_dist(), np.eye(3),
                             dt.default_P())
    with pytest.raises(CalibrationFileError, match="NaN"):
        K = dt.default_K()
        K[0, 0] = np.nan
        IntrinsicCalibration("/x", 640, 480, K, "plumb_bob", dt.default_dist(), np.eye(3), dt.default_P())


# --------------------------------------------------------------------------- extrinsic files
def _write_ext(tmp_path, text) -> Path:
    p = tmp_path / "camera_extrinsic" / "bot.yaml"
    p.parent.mkdir(parents=True, exist_ok=True)
    p.write_text(text)
    return p


@pytest.mark.parametrize("text,pattern", [
    ("foo: 1\n", "missing field 'homography'"),
    ("homography: 3\n", "must be a list of 9 numbers"),
    ("homography: [1, 0, 0, 0, 1, 0, 0, 0]\n", "has 8 values; expected 9"),
    ("homography: [1, 0, 0, 0, 1, -1, 0, 0, .nan]\n", r"homography\[8\] is nan"),
    ("homography: [1, 0, 0, 0, 1, -1, 0, 0, '1']\n", r"homography\[8\] is str"),
    ("homography: [1, 2, 3, 2, 4, -6, 0, 0, 1]\n", "singular"),
    ("homography: [0, 0, 0, 0, 0, 0, 0, 0, 0]\n", "singular"),
])
def test_bad_extrinsics(tmp_path, text, pattern):
    p = _write_ext(tmp_path, text)
    with pytest.raises(CalibrationFileError, match=pattern) as e:
        load_extrinsics(p)
    assert str(p) in str(e.value)


def test_positive_h12_is_read_with_a_warning_and_refused_when_writing(tmp_path):
    """Duckietown's H[1][2] rule applies when writing; its reader (and the kit's) takes such files."""
    H = list(dt.DEFAULT_HOMOGRAPHY)
    H[5] = 0.3280241
    p = _write_ext(tmp_path, yaml.safe_dump({"homography": H}, default_flow_style=None))
    with pytest.warns(CalibrationFileWarning, match=r"H\[1\]\[2\] = 0.328024 > 0.*rotated 180 degrees") as w:
        got = load_extrinsics(p)
    assert len(w) == 1 and str(p) in str(w[0].message)
    np.testing.assert_array_equal(got.ravel(), H)
    with pytest.raises(CalibrationFileError, match=r"H\[1\]\[2\] = 0.328024 > 0.*corrupt") as e:
        save_extrinsics(np.array(H).reshape(3, 3), tmp_path, "bot")
    assert "recalibrate" in str(e.value)
    assert yaml.safe_load(p.read_text())["homography"][5] == 0.3280241


# --------------------------------------------------------------------------- writing
def test_refuses_default_and_bad_names(calib_dir):
    c = load_intrinsics(intrinsic_path(calib_dir, "default"))
    before = intrinsic_path(calib_dir, "default").read_bytes()
    with pytest.raises(CalibrationFileError,
                       match="default.yaml is the factory calibration and is never overwritten; pass --robot NAME"):
        save_intrinsics(c, calib_dir, "default")
    with pytest.raises(CalibrationFileError, match="never overwritten"):
        save_extrinsics(dt.default_H(), calib_dir, "default")
    for bad in ["../evil", "a/b", "a\\b", "", ".hidden", "x..y", "bot name"]:
        with pytest.raises(CalibrationFileError, match="robot name"):
            save_intrinsics(c, calib_dir, bad)
    with pytest.raises(CalibrationFileError, match="robot name"):
        intrinsic_path(calib_dir, "../x")
    assert intrinsic_path(calib_dir, "default").read_bytes() == before
    assert sorted(os.listdir(calib_dir / "camera_intrinsic")) == ["default.yaml"]


def test_backup_keeps_previous(calib_dir):
    c = load_intrinsics(intrinsic_path(calib_dir, "default"))
    p = save_intrinsics(c, calib_dir, "bot")
    assert not p.with_name("bot.yaml.bak").exists()
    first = p.read_bytes()
    K2 = c.K.copy()
    K2[0, 0] = 316.25
    c2 = IntrinsicCalibration(c.camera_name, c.width, c.height, K2, c.distortion_model, c.D, c.R, c.P)
    save_intrinsics(c2, calib_dir, "bot")
    bak = p.with_name("bot.yaml.bak")
    assert bak.read_bytes() == first
    assert load_intrinsics(p).K[0, 0] == 316.25
    assert load_intrinsics(bak) == c
    # extrinsics too
    e = save_extrinsics(dt.default_H(), calib_dir, "bot")
    H2 = dt.default_H() * 1.0
    H2[0, 2] = -0.2
    save_extrinsics(H2, calib_dir, "bot")
    assert load_extrinsics(e)[0, 2] == -0.2
    np.testing.assert_array_equal(load_extrinsics(e.with_name("bot.yaml.bak")), dt.default_H())
    # no temporary files left behind
    assert not [f for f in os.listdir(p.parent) if f.endswith(".tmp")]
    assert not [f for f in os.listdir(e.parent) if f.endswith(".tmp")]


def test_creates_missing_folders(tmp_path):
    p = save_extrinsics(dt.default_H(), tmp_path / "new" / "calibrations", "bot")
    assert p == tmp_path / "new" / "calibrations" / "camera_extrinsic" / "bot.yaml"
    np.testing.assert_array_equal(load_extrinsics(p), dt.default_H())


def _state(d: Path) -> dict:
    return {f: (d / f).read_bytes() for f in sorted(os.listdir(d))}


def test_failed_replace_leaves_previous_file(calib_dir, monkeypatch):
    c = load_intrinsics(intrinsic_path(calib_dir, "default"))
    p = save_intrinsics(c, calib_dir, "bot")
    before = p.read_bytes()
    real_replace = os.replace

    def failing_replace(src, dst):
        if Path(dst) == p:
            raise OSError(28, "No space left on device")
        return real_replace(src, dst)

    monkeypatch.setattr(cf.os, "replace", failing_replace)
    K2 = c.K.copy()
    K2[0, 0] = 300.5
    c2 = IntrinsicCalibration(c.camera_name, c.width, c.height, K2, c.distortion_model, c.D, c.R, c.P)
    with pytest.raises(CalibrationFileError, match="could not be written .*previous file is unchanged"):
        save_intrinsics(c2, calib_dir, "bot")
    assert p.read_bytes() == before
    assert not [f for f in os.listdir(p.parent) if f.endswith(".tmp")]


def test_failed_dump_leaves_previous_file(calib_dir, monkeypatch):
    p = save_extrinsics(dt.default_H(), calib_dir, "bot")
    before = _state(p.parent)

    def boom(*a, **k):
        raise yaml.representer.RepresenterError("cannot represent")

    monkeypatch.setattr(cf.yaml, "safe_dump", boom)
    with pytest.raises(yaml.YAMLError):
        save_extrinsics(dt.default_H() * 2, calib_dir, "bot")
    assert _state(p.parent) == before


def test_failed_write_midway_removes_temp(calib_dir, monkeypatch):
    p = save_extrinsics(dt.default_H(), calib_dir, "bot")
    before = _state(p.parent)

    def bad_fsync(fd):
        raise OSError(5, "Input/output error")

    monkeypatch.setattr(cf.os, "fsync", bad_fsync)
    with pytest.raises(CalibrationFileError, match="Input/output error"):
        save_extrinsics(dt.default_H() * 2, calib_dir, "bot")
    assert _state(p.parent) == before


def test_read_only_folder():
    """Real under root too: the second write runs as ``nobody`` (root ignores a folder's permissions)."""
    with shared_tmp() as d:
        p = save_extrinsics(dt.default_H(), d / "calibrations", "bot")
        for folder in (d / "calibrations", p.parent):
            os.chmod(folder, 0o555)
        before = _state(p.parent)
        ok, text = run_unprivileged(save_extrinsics, dt.default_H() * 2, d / "calibrations", "bot")
        assert not ok
        assert text.startswith("CalibrationFileError") and "could not be written" in text, text
        assert "Permission denied" in text and "previous file is unchanged" in text
        assert _state(p.parent) == before
        np.testing.assert_array_equal(load_extrinsics(p), dt.default_H())


# --------------------------------------------------------------------------- rights of replaced files
@pytest.mark.parametrize("mode", [0o644, 0o640, 0o600, 0o664])
def test_replaced_file_keeps_its_mode(calib_dir, mode):
    p = save_extrinsics(dt.default_H(), calib_dir, "bot")
    os.chmod(p, mode)
    save_extrinsics(dt.default_H() * 2, calib_dir, "bot")
    assert stat.S_IMODE(os.stat(p).st_mode) == mode
    assert stat.S_IMODE(os.stat(p.with_name("bot.yaml.bak")).st_mode) == mode
    c = load_intrinsics(intrinsic_path(calib_dir, "default"))
    q = save_intrinsics(c, calib_dir, "bot")
    os.chmod(q, mode)
    save_intrinsics(c, calib_dir, "bot")
    assert stat.S_IMODE(os.stat(q).st_mode) == mode


@pytest.mark.parametrize("umask", [0o022, 0o027, 0o077, 0o002])
def test_new_file_follows_umask(tmp_path, umask):
    old = os.umask(umask)
    try:
        p = save_extrinsics(dt.default_H(), tmp_path, "bot")
    finally:
        os.umask(old)
    assert stat.S_IMODE(os.stat(p).st_mode) == 0o666 & ~umask


def test_replaced_file_stays_readable_to_others():
    """A 0644 file replaced by another user's write stays readable to everyone (was 0600)."""
    with shared_tmp() as d:
        folder = d / "calibrations" / "camera_extrinsic"
        folder.mkdir(parents=True)
        os.chmod(d / "calibrations", 0o777)
        os.chmod(folder, 0o777)
        p = save_extrinsics(dt.default_H(), d / "calibrations", "bot")
        os.chmod(p, 0o644)
        ok, text = run_unprivileged(save_extrinsics, dt.default_H() * 2, d / "calibrations", "bot")
        assert ok, text
        assert stat.S_IMODE(os.stat(p).st_mode) == 0o644
        np.testing.assert_array_equal(load_extrinsics(p), dt.default_H() * 2)


def test_stale_temporaries_are_cleaned_on_next_write(calib_dir):
    p = save_extrinsics(dt.default_H(), calib_dir, "bot")
    stale = [p.parent / ".bot.yaml.k1ll3d_x.tmp", p.parent / ".bot.yaml.bak.abcd_123.tmp"]
    fresh = p.parent / ".bot.yaml.in-flight.tmp"  # not the kit's pattern: someone else's, left alone
    young = p.parent / ".bot.yaml.wr1t1ng_.tmp"  # the kit's pattern, but a live writer's (recent)
    other = p.parent / ".other.yaml.zzzzzzzz.tmp"  # another robot's: not ours to judge
    for f in [*stale, fresh, young, other]:
        f.write_text("partial")
    old = time.time() - cf.STALE_TMP_SECONDS - 60
    for f in [*stale, fresh, other]:
        os.utime(f, (old, old))
    save_extrinsics(dt.default_H() * 2, calib_dir, "bot")
    left = sorted(f for f in os.listdir(p.parent) if f.endswith(".tmp"))
    assert left == sorted([fresh.name, young.name, other.name])
