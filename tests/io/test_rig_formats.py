"""Rig files in anipose, COLMAP and EasyMocap formats (docs/CONVENTIONS.md §3): round trips, hand-written
files that project as computed by hand in each format's own convention, and errors that
name the file, the camera and the line or key."""

import re

import jax.numpy as jnp
import numpy as np
import pytest
from helpers import x64

import cdog_jax
from cdog_jax.io import load_rig, save_rig
from cdog_jax.io._rig_files import FORMATS
from cdog_jax.io._rotations import (
    quaternion_from_rotation,
    rodrigues_from_rotation,
    rotation_from_quaternion,
    rotation_from_rodrigues,
)
from cdog_jax.synthetic import default_rig
from cdog_jax.synthetic._rig import negate_intrinsics

X_WORLD = np.array([0.3, -0.2, 1.5])


def _write(path, text, newline=None):
    with open(path, "w", encoding="utf-8", newline=newline) as f:
        f.write(text)
    return path


def _expm_skew(r):
    """exp([r]_x) by its power series: a check of Rodrigues independent of the library."""
    S = np.array([[0.0, -r[2], r[1]], [r[2], 0.0, -r[0]], [-r[1], r[0], 0.0]])
    out, term = np.eye(3), np.eye(3)
    for k in range(1, 40):
        term = term @ S / k
        out = out + term
    return out


def _pixel(K, R, t, X):
    h = K @ (R @ X + t)
    return h[:2] / h[2]


def _project(loaded):
    xy, ok = cdog_jax.project(loaded.rig, jnp.asarray(X_WORLD, loaded.rig.K.dtype))
    assert np.all(np.asarray(ok))
    return np.asarray(xy, np.float64)


def _raises(*fragments):
    return pytest.raises(ValueError, match=".*".join(re.escape(str(f)) for f in fragments))


# Rotations --------------------------------------------------------------------------------


@pytest.mark.parametrize("angle", [0.0, 1e-12, 1e-7, 0.4, 2.0, np.pi - 1e-9, np.pi])
def test_rotation_conversions_are_exact(angle):
    axis = np.array([0.48, -0.6, 0.64])
    r = axis * angle
    R = rotation_from_rodrigues(r)
    np.testing.assert_allclose(R, _expm_skew(r), atol=1e-15)
    np.testing.assert_allclose(R.T @ R, np.eye(3), atol=1e-15)
    r_back = rodrigues_from_rotation(R)
    if angle < 3.0:
        np.testing.assert_allclose(r_back, r, rtol=1e-12, atol=1e-300)
    np.testing.assert_allclose(rotation_from_rodrigues(r_back), R, atol=1e-15)
    q = quaternion_from_rotation(R)
    assert q[0] >= 0 and abs(q @ q - 1) < 1e-15
    np.testing.assert_allclose(rotation_from_quaternion(q), R, atol=1e-15)


# anipose ----------------------------------------------------------------------------------

# cam_10 before cam_2 in the file (and as strings): views must come in numeric order.
ANIPOSE_TOML = """\
[cam_10]
name = "right"
size = [1280, 720]
matrix = [[1000.0, 0.0, 640.0], [0.0, 1000.0, 360.0], [0.0, 0.0, 1.0]]
distortions = [0.0, 0.0, 0.0, 0.0, 0.0]
rotation = [0.3, -0.2, 0.1]
translation = [0.5, 0.1, 3.0]

[cam_2]
name = "left"
size = [ 640, 480,]
matrix = [ [ 800.0, 0.0, 320.0,], [ 0.0, 790.0, 240.0,], [ 0.0, 0.0, 1.0,],]
distortions = [ 0.1, -0.05, 0.001, 0.002,]
rotation = [ 0.0, 0.5, 0.0,]
translation = [ 0.1, -0.2, 4.0,]

[metadata]
adjusted = false
error = 0.31
"""


def test_anipose_projects_as_by_hand(tmp_path):
    path = _write(tmp_path / "calibration.toml", ANIPOSE_TOML)
    loaded = load_rig(path)
    assert loaded.names == ("left", "right")
    np.testing.assert_array_equal(loaded.view_sizes, [[640, 480], [1280, 720]])
    assert loaded.view_sizes.dtype == np.int64 and loaded.image_size is None  # sizes differ
    np.testing.assert_array_equal(loaded.dist, [[0.1, -0.05, 0.001, 0.002, 0.0], [0.0] * 5])
    c, s = np.cos(0.5), np.sin(0.5)
    R_left = np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])  # 0.5 rad about y
    expected = [
        _pixel(
            np.array([[800.0, 0, 320], [0, 790, 240], [0, 0, 1]]),
            R_left,
            np.array([0.1, -0.2, 4.0]),
            X_WORLD,
        ),
        _pixel(
            np.diag([1000.0, 1000.0, 1.0]) + [[0, 0, 640], [0, 0, 360], [0, 0, 0]],
            _expm_skew(np.array([0.3, -0.2, 0.1])),
            np.array([0.5, 0.1, 3.0]),
            X_WORLD,
        ),
    ]
    np.testing.assert_allclose(_project(loaded), expected, atol=2e-3)


def test_anipose_round_trip(tmp_path):
    with x64():
        rig = negate_intrinsics(default_rig(), [3])
        dist = np.random.default_rng(0).normal(size=(10, 5)) * 0.1
        names = [f'cam "{m}"\t✓' for m in range(10)]  # quotes, a tab, non-ASCII
        sizes = np.array([[640 + m, 480] for m in range(10)])
        save_rig(
            tmp_path / "calib.toml", rig, format="anipose", image_size=sizes, dist=dist, names=names
        )
        loaded = load_rig(tmp_path / "calib.toml")
        K = np.asarray(rig.K)
        np.testing.assert_allclose(np.asarray(loaded.rig.K), K / K[:, 2:3, 2:3], rtol=1e-15)
        np.testing.assert_allclose(np.asarray(loaded.rig.R), np.asarray(rig.R), atol=1e-14)
        np.testing.assert_array_equal(np.asarray(loaded.rig.t), np.asarray(rig.t))
        np.testing.assert_allclose(
            _project(loaded), np.asarray(cdog_jax.project(rig, jnp.asarray(X_WORLD))[0]), rtol=1e-12
        )
    np.testing.assert_array_equal(loaded.dist, dist)
    np.testing.assert_array_equal(loaded.view_sizes, sizes)
    assert loaded.names == tuple(names)


def _anipose_file(tmp_path, old, new):
    assert old in ANIPOSE_TOML
    return _write(tmp_path / "calibration.toml", ANIPOSE_TOML.replace(old, new))


def test_anipose_too_many_distortions(tmp_path):
    path = _anipose_file(
        tmp_path, "0.002,]", "0.002, 0.0, 0.1, 0.0, 0.0]"
    )  # k4 = 0.1: the rational model
    with _raises(
        path,
        "view 0 (camera 'left', section [cam_2])",
        'key "distortions"',
        "expected 4 or 5",
        "got 8",
        "rational",
    ):
        load_rig(path)


def test_anipose_missing_key(tmp_path):
    path = _anipose_file(tmp_path, "rotation = [0.3, -0.2, 0.1]\n", "")
    with _raises(path, "view 1 (camera 'right', section [cam_10])", 'missing key "rotation"'):
        load_rig(path)


def test_anipose_fisheye_on_some_cameras_only(tmp_path):
    path = _anipose_file(tmp_path, 'name = "right"\n', 'name = "right"\nfisheye = true\n')
    with _raises(
        path,
        "view 1 (camera 'right'",
        '"distortions" (fisheye: k1, k2, k3, k4)',
        "expected shape (4,)",
    ):
        load_rig(path)
    text = ANIPOSE_TOML.replace('name = "right"\n', 'name = "right"\nfisheye = true\n')
    path = _write(
        tmp_path / "calibration.toml",
        text.replace("[0.0, 0.0, 0.0, 0.0, 0.0]", "[0.0, 0.0, 0.0, 0.0]"),
    )
    with _raises(path, "view 0 is an OpenCV (k1, k2, p1, p2, k3) lens and view 1 is not"):
        load_rig(path)


def test_anipose_missing_size(tmp_path):
    path = _anipose_file(tmp_path, "size = [1280, 720]\n", "")
    with _raises(path, "view 1 (camera 'right')", 'missing key "size"'):
        load_rig(path)


def test_anipose_no_cameras_duplicates_and_bad_toml(tmp_path):
    path = _write(tmp_path / "empty.toml", "[metadata]\nerror = 1.0\n")
    with _raises(path, "no [cam_N] sections", "['metadata']"):
        load_rig(path)
    path = _write(tmp_path / "dup.toml", ANIPOSE_TOML.replace("[cam_10]", "[cam_02]"))
    with _raises(path, "[cam_02]", "[cam_2]", "same camera number 2"):
        load_rig(path)
    path = _write(tmp_path / "bad.toml", "[cam_0\nname = 1")
    with _raises(path, "not valid TOML"):
        load_rig(path)


def test_anipose_bad_values_name_the_camera(tmp_path):
    path = _anipose_file(tmp_path, "translation = [0.5, 0.1, 3.0]", "translation = [0.5, 0.1]")
    with _raises(
        path,
        "view 1 (camera 'right', section [cam_10])",
        'key "translation"',
        "expected shape (3,)",
        "got (2,)",
    ):
        load_rig(path)
    # A singular K is caught by rig_from_arrays: the message still names file and camera.
    path = _anipose_file(tmp_path, "[0.0, 1000.0, 360.0]", "[0.0, 0.0, 0.0]")
    with _raises(path, "K of view 1 (camera 'right') is singular"):
        load_rig(path)


# COLMAP -----------------------------------------------------------------------------------

COLMAP_CAMERAS = """\
# Camera list with one line of data per camera:
#   CAMERA_ID, MODEL, WIDTH, HEIGHT, PARAMS[]
# Number of cameras: 2
1 PINHOLE 640 480 800 790 320.5 240.5
3 SIMPLE_RADIAL 1280 720 1000 640 360 0.01
"""
# Image 7 is listed first and has points; image 2 has an empty POINTS2D line.
COLMAP_IMAGES = """\
# Image list with two lines of data per image:
#   IMAGE_ID, QW, QX, QY, QZ, TX, TY, TZ, CAMERA_ID, NAME
#   POINTS2D[] as (X, Y, POINT3D_ID)
# Number of images: 2, mean observations per image: 1
7 0.5 0.5 0.5 0.5 0.2 -0.1 5.0 3 cam7.png
100.0 200.0 -1 300.0 400.0 5

2 0.9659258262890683 0.0 0.0 0.25881904510252074 0.1 0.2 4.0 1 cam2.png

"""


def _colmap_folder(tmp_path, cameras=COLMAP_CAMERAS, images=COLMAP_IMAGES):
    folder = tmp_path / "sparse"
    folder.mkdir(exist_ok=True)
    _write(folder / "cameras.txt", cameras)
    _write(folder / "images.txt", images)
    return folder


def test_colmap_projects_as_by_hand(tmp_path):
    folder = _colmap_folder(tmp_path)
    loaded = load_rig(folder)
    assert loaded.names == ("cam2.png", "cam7.png")  # IMAGE_ID order
    np.testing.assert_array_equal(loaded.view_sizes, [[640, 480], [1280, 720]])
    np.testing.assert_array_equal(loaded.dist, [[0.0] * 5, [0.01, 0, 0, 0, 0]])
    # COLMAP convention: q = (w, x, y, z) world→camera; pixel centres at +0.5.
    c, s = np.cos(np.pi / 6), np.sin(np.pi / 6)
    R2 = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])  # 30° about z
    R7 = np.array([[0.0, 0.0, 1.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])  # q = (½, ½, ½, ½)
    X2, X7 = R2 @ X_WORLD + [0.1, 0.2, 4.0], R7 @ X_WORLD + [0.2, -0.1, 5.0]
    colmap_px = [
        [800 * X2[0] / X2[2] + 320.5, 790 * X2[1] / X2[2] + 240.5],
        [1000 * X7[0] / X7[2] + 640, 1000 * X7[1] / X7[2] + 360],
    ]
    np.testing.assert_allclose(_project(loaded), np.array(colmap_px) - 0.5, atol=2e-3)
    # The path of either file reads the folder.
    for file in ("cameras.txt", "images.txt"):
        np.testing.assert_array_equal(
            np.asarray(load_rig(folder / file).rig.K), np.asarray(loaded.rig.K)
        )


def test_colmap_round_trip_with_negated_K(tmp_path):
    with x64():
        rig = negate_intrinsics(default_rig(), [0, 4])  # K[2,2] = -1: written as K / K[2,2]
        M = rig.num_views
        dist = np.zeros((M, 5))
        dist[::2, :4] = (
            np.random.default_rng(1).normal(size=(5, 4)) * 0.05
        )  # OPENCV; odd views PINHOLE
        sizes = np.array([[640, 480]] * (M - 1) + [[1920, 1080]])
        save_rig(tmp_path / "model", rig, format="colmap", image_size=sizes, dist=dist)
        loaded = load_rig(tmp_path / "model")
        K = np.asarray(rig.K)
        np.testing.assert_allclose(
            np.asarray(loaded.rig.K), K / K[:, 2:3, 2:3], rtol=1e-12, atol=1e-12
        )
        np.testing.assert_allclose(np.asarray(loaded.rig.R), np.asarray(rig.R), atol=1e-14)
        np.testing.assert_array_equal(np.asarray(loaded.rig.t), np.asarray(rig.t))
        np.testing.assert_allclose(
            _project(loaded), np.asarray(cdog_jax.project(rig, jnp.asarray(X_WORLD))[0]), rtol=1e-12
        )
    np.testing.assert_array_equal(loaded.dist, dist)
    np.testing.assert_array_equal(loaded.view_sizes, sizes)
    assert loaded.image_size is None and loaded.names == tuple(f"view_{m}" for m in range(M))
    cameras = (tmp_path / "model" / "cameras.txt").read_text().splitlines()
    assert cameras[3].split()[1] == "OPENCV" and cameras[4].split()[1] == "PINHOLE"
    assert (tmp_path / "model" / "points3D.txt").exists()


def test_colmap_writer_refuses_what_colmap_cannot_hold(tmp_path):
    rig = default_rig(num_views=2)
    skewed = cdog_jax.Rig(rig.K.at[0, 0, 1].set(1.5), rig.R, rig.t)
    with _raises("view 0", "skew K[0,1] = 1.5"):
        save_rig(tmp_path / "b", skewed, format="colmap", image_size=(640, 480))
    with _raises("names[1] = 'b c'", "whitespace"):
        save_rig(tmp_path / "c", rig, format="colmap", image_size=(640, 480), names=["a", "b c"])
    with _raises("image_size must be (width, height) or have shape (M, 2) = (2, 2)"):
        save_rig(tmp_path / "d", rig, format="colmap", image_size=[[640, 480]] * 3)


def test_colmap_unknown_model(tmp_path):
    folder = _colmap_folder(
        tmp_path, cameras=COLMAP_CAMERAS.replace("SIMPLE_RADIAL", "THIN_PRISM_FISHEYE")
    )
    with _raises(
        folder / "cameras.txt",
        "line 5, camera 3",
        "unsupported camera model 'THIN_PRISM_FISHEYE'",
        "PINHOLE",
    ):
        load_rig(folder)


def test_colmap_wrong_parameter_count(tmp_path):
    folder = _colmap_folder(tmp_path, cameras=COLMAP_CAMERAS.replace("320.5 240.5", "320.5"))
    with _raises(
        folder / "cameras.txt",
        "line 4, camera 1",
        "PINHOLE takes 4 parameters (fx, fy, cx, cy); got 3",
    ):
        load_rig(folder)


def test_colmap_bad_quaternion_norm(tmp_path):
    folder = _colmap_folder(
        tmp_path, images=COLMAP_IMAGES.replace("7 0.5 0.5 0.5 0.5", "7 0.5 0.5 0.5 0.6")
    )
    with _raises(
        folder / "images.txt", "line 5", "view 1 (image 7 'cam7.png')", "norm 1.0", "expected 1"
    ):
        load_rig(folder)


def test_colmap_dropped_points_line_and_unknown_camera(tmp_path):
    # An exporter that dropped the empty POINTS2D lines: image 2's line would be swallowed.
    images = (
        "2 0.9659258262890683 0.0 0.0 0.25881904510252074 0.1 0.2 4.0 1 cam2.png\n"
        "7 0.5 0.5 0.5 0.5 0.2 -0.1 5.0 3 cam7.png\n"
        "100.0 200.0 -1 300.0 400.0 5\n"
    )
    folder = _colmap_folder(tmp_path, images=images)
    with _raises(
        folder / "images.txt", "line 2", "POINTS2D line of image 2 'cam2.png'", "got 10 fields"
    ):
        load_rig(folder)
    folder = _colmap_folder(
        tmp_path, images=COLMAP_IMAGES.replace("4.0 1 cam2.png", "4.0 9 cam2.png")
    )
    with _raises(
        folder / "images.txt",
        "line 8",
        "view 0 (image 2 'cam2.png')",
        "CAMERA_ID 9 is not in",
        "[1, 3]",
    ):
        load_rig(folder)


def test_colmap_singular_K_names_the_image(tmp_path):
    folder = _colmap_folder(
        tmp_path, cameras=COLMAP_CAMERAS.replace("640 480 800 790", "640 480 800 0")
    )
    with _raises(folder, "K of view 0 (camera 'cam2.png') is singular"):
        load_rig(folder)


def test_colmap_missing_file_and_binary_model(tmp_path):
    folder = _colmap_folder(tmp_path)
    (folder / "images.txt").unlink()
    with _raises(folder / "cameras.txt", "missing", "images.txt"):
        load_rig(folder / "cameras.txt")
    binary = tmp_path / "bin"
    binary.mkdir()
    for name in ("cameras.bin", "images.bin"):
        (binary / name).write_bytes(b"\0")
    with _raises(binary, "binary COLMAP model", "model_converter"):
        load_rig(binary)


# EasyMocap --------------------------------------------------------------------------------

# As OpenCV writes it (3-space indent, "0." numbers, data over two lines), names unquoted
# and quoted; camera 02 has only a Rodrigues vector, and 4 distortion coefficients.
EASYMOCAP_INTRI = """\
%YAML:1.0
---
names:
   - 01
   - "02"
K_01: !!opencv-matrix
   rows: 3
   cols: 3
   dt: d
   data: [ 8.0000000000000000e+02, 0., 3.2000000000000000e+02, 0.,
       7.9000000000000000e+02, 2.4000000000000000e+02, 0., 0., 1. ]
dist_01: !!opencv-matrix
   rows: 1
   cols: 5
   dt: d
   data: [ 0.1, -0.05, 0.001, 0.002, 0.003 ]
K_02: !!opencv-matrix
  rows: 3
  cols: 3
  dt: d
  data: [1000.0, 0.0, 640.0, 0.0, 1000.0, 360.0, 0.0, 0.0, 1.0]
dist_02: !!opencv-matrix
  rows: 4
  cols: 1
  dt: d
  data: [0.01, 0.02, 0.0, 0.0]
"""
EASYMOCAP_EXTRI = """\
%YAML:1.0
---
names: [ "01", "02" ]
R_01: !!opencv-matrix
   rows: 3
   cols: 1
   dt: d
   data: [ 0., 0., 1.5707963267948966 ]
Rot_01: !!opencv-matrix
   rows: 3
   cols: 3
   dt: d
   data: [ 0., -1., 0., 1., 0., 0., 0., 0., 1. ]
T_01: !!opencv-matrix
   rows: 3
   cols: 1
   dt: d
   data: [ 0.1, -0.2, 4.0 ]
R_02: !!opencv-matrix
   rows: 3
   cols: 1
   dt: d
   data: [ 0.3, -0.2, 0.1 ]
T_02: !!opencv-matrix
   rows: 1
   cols: 3
   dt: d
   data: [ 0.5, 0.1, 3.0 ]
"""


def _easymocap_folder(tmp_path, intri=EASYMOCAP_INTRI, extri=EASYMOCAP_EXTRI):
    folder = tmp_path / "calib"
    folder.mkdir(exist_ok=True)
    _write(folder / "intri.yml", intri, newline="\r\n")  # EasyMocap writes CRLF
    _write(folder / "extri.yml", extri)
    return folder


def test_easymocap_projects_as_by_hand(tmp_path):
    folder = _easymocap_folder(tmp_path)
    loaded = load_rig(folder)
    assert loaded.names == ("01", "02") and loaded.view_sizes is None and loaded.image_size is None
    np.testing.assert_array_equal(
        loaded.dist, [[0.1, -0.05, 0.001, 0.002, 0.003], [0.01, 0.02, 0.0, 0.0, 0.0]]
    )
    expected = [
        _pixel(
            np.array([[800.0, 0, 320], [0, 790, 240], [0, 0, 1]]),
            np.array([[0.0, -1, 0], [1, 0, 0], [0, 0, 1]]),
            np.array([0.1, -0.2, 4.0]),
            X_WORLD,
        ),
        _pixel(
            np.array([[1000.0, 0, 640], [0, 1000, 360], [0, 0, 1]]),
            _expm_skew(np.array([0.3, -0.2, 0.1])),
            np.array([0.5, 0.1, 3.0]),
            X_WORLD,
        ),
    ]
    np.testing.assert_allclose(_project(loaded), expected, atol=2e-3)
    assert load_rig(folder / "extri.yml").names == ("01", "02")


def test_easymocap_round_trip(tmp_path):
    with x64():
        rig = negate_intrinsics(default_rig(), [2])
        dist = np.random.default_rng(2).normal(size=(10, 5)) * 0.1
        names = [f"cam-{m}_x" for m in range(10)]
        save_rig(tmp_path / "out", rig, format="easymocap", dist=dist, names=names)
        loaded = load_rig(tmp_path / "out")
        K = np.asarray(rig.K)
        np.testing.assert_allclose(np.asarray(loaded.rig.K), K / K[:, 2:3, 2:3], rtol=1e-15)
        np.testing.assert_allclose(
            np.asarray(loaded.rig.R), np.asarray(rig.R), atol=1e-14
        )  # R_, as EasyMocap reads it
        np.testing.assert_array_equal(np.asarray(loaded.rig.t), np.asarray(rig.t))
    np.testing.assert_array_equal(loaded.dist, dist)
    assert loaded.names == tuple(names)
    text = (tmp_path / "out" / "extri.yml").read_text()
    assert (
        text.startswith('%YAML:1.0\n---\nnames:\n   - "cam-0_x"\n')
        and "Rot_cam-9_x: !!opencv-matrix" in text
    )
    with _raises("names[0] = 'a.b'", "letters, digits"):
        save_rig(tmp_path / "bad", default_rig(num_views=1), format="easymocap", names=["a.b"])


def test_easymocap_missing_names(tmp_path):
    intri = EASYMOCAP_INTRI.replace('names:\n   - 01\n   - "02"\n', "")
    folder = _easymocap_folder(tmp_path, intri=intri)
    with _raises(folder / "intri.yml", 'missing key "names"'):
        load_rig(folder)


def test_easymocap_missing_key(tmp_path):
    extri = EASYMOCAP_EXTRI[: EASYMOCAP_EXTRI.index("T_02")]
    folder = _easymocap_folder(tmp_path, extri=extri)
    with _raises(folder / "extri.yml", "view 1 (camera '02')", 'missing key "T_02"'):
        load_rig(folder)
    extri = EASYMOCAP_EXTRI.replace("R_02", "Q_02")
    folder = _easymocap_folder(tmp_path, extri=extri)
    with _raises(folder / "extri.yml", "view 1 (camera '02')", 'missing key "R_02" (or "Rot_02")'):
        load_rig(folder)


def test_easymocap_too_many_distortion_coefficients(tmp_path):
    intri = EASYMOCAP_INTRI.replace(
        "rows: 4\n  cols: 1\n  dt: d\n  data: [0.01, 0.02, 0.0, 0.0]",
        "rows: 8\n  cols: 1\n  dt: d\n  data: [0.01, 0.02, 0, 0, 0, 0.1, 0, 0]",
    )
    folder = _easymocap_folder(tmp_path, intri=intri)
    with _raises(
        folder / "intri.yml",
        "line 22",
        "view 1 (camera '02')",
        'key "dist_02"',
        "expected 4 or 5",
        "got 8",
    ):
        load_rig(folder)


def test_easymocap_rotation_disagrees(tmp_path):
    extri = EASYMOCAP_EXTRI.replace("1.5707963267948966", "1.4")
    folder = _easymocap_folder(tmp_path, extri=extri)
    with _raises(
        folder / "extri.yml",
        "line 9",
        "view 0 (camera '01')",
        '"Rot_01" and the rotation of "R_01" (line 4) differ',
    ):
        load_rig(folder)


def test_easymocap_malformed_matrix_and_names(tmp_path):
    extri = EASYMOCAP_EXTRI.replace("data: [ 0.1, -0.2, 4.0 ]", "data: [ 0.1, -0.2 ]")
    folder = _easymocap_folder(tmp_path, extri=extri)
    with _raises(
        folder / "extri.yml",
        "line 14",
        'key "T_01"',
        "rows × cols = 3 × 1 but 'data' holds 2 numbers",
    ):
        load_rig(folder)
    extri = EASYMOCAP_EXTRI.replace('names: [ "01", "02" ]', 'names: [ "01", "03" ]')
    folder = _easymocap_folder(tmp_path, extri=extri)
    with _raises(folder / "extri.yml", "line 3", 'key "names"', "differs from"):
        load_rig(folder)
    intri = EASYMOCAP_INTRI.replace("K_02: !!opencv-matrix", "K_02 !!opencv-matrix")
    folder = _easymocap_folder(tmp_path, intri=intri)
    with _raises(folder / "intri.yml", "line 17", "expected a top-level 'key: value' line"):
        load_rig(folder)


# Format detection and the new RigFile fields ----------------------------------------------


def test_format_detection(tmp_path):
    assert {"anipose", "colmap", "easymocap"} <= set(FORMATS)
    rig = default_rig(num_views=2)
    save_rig(tmp_path / "calib.toml", rig, format="anipose", image_size=(640, 480))
    save_rig(tmp_path / "colmap", rig, format="colmap", image_size=(640, 480))
    save_rig(tmp_path / "emc", rig, format="easymocap")
    assert load_rig(tmp_path / "calib.toml").names == ("cam_0", "cam_1")
    assert load_rig(tmp_path / "colmap").image_size == (640, 480)
    assert load_rig(tmp_path / "emc" / "intri.yml").names == ("00", "01")
    # A folder with intri.yml but no extri.yml is read as EasyVis (and fails as one).
    (tmp_path / "emc" / "extri.yml").unlink()
    with _raises(tmp_path / "emc", "zero views"):
        load_rig(tmp_path / "emc")
    with _raises(tmp_path / "emc", "missing", "extri.yml"):
        load_rig(tmp_path / "emc", format="easymocap")
    # The older formats fill the new fields: one size for all views, no names.
    save_rig(tmp_path / "rig.json", rig, format="json", image_size=(800, 600))
    loaded = load_rig(tmp_path / "rig.json")
    np.testing.assert_array_equal(loaded.view_sizes, [[800, 600], [800, 600]])
    assert loaded.image_size == (800, 600) and loaded.names is None
