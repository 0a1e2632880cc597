"""Rig formats as their tools write and read them: COLMAP FULL_OPENCV and OPENCV_FISHEYE,
EasyMocap's ``R_`` and ``H_``/``W_``, anipose's required ``size`` and camera order by name,
nerfstudio ``transforms.json``, the fisheye model in every format that has one, and a
float64 request that 64-bit JAX cannot honour."""

import json
import re

import jax.numpy as jnp
import numpy as np
import pytest
from helpers import x64
from test_rig_formats import (
    ANIPOSE_TOML,
    EASYMOCAP_EXTRI,
    EASYMOCAP_INTRI,
    _easymocap_folder,
    _write,
)

import cdog_jax
from cdog_jax.geometry import Fisheye
from cdog_jax.io import load_rig, save_rig
from cdog_jax.io._rotations import rotation_from_rodrigues
from cdog_jax.synthetic import default_rig

X = np.array([[0.3, -0.2, 1.5], [0.1, 0.2, 0.3]])
FISHEYE = np.array([[0.05, -0.01, 0.002, -0.0004], [0.02, 0.0, 0.0, 0.001], [0.0, 0.01, 0.0, 0.0]])


def _pixels(loaded):
    xy, ok = cdog_jax.project(loaded.rig, jnp.asarray(X, loaded.rig.K.dtype), dist=loaded.dist)
    assert np.asarray(ok).all()
    return np.asarray(xy, np.float64)


def test_colmap_full_opencv_written_for_k3_and_read_back(tmp_path):
    with x64():
        rig = default_rig(num_views=3, dtype=jnp.float64)
        dist = np.zeros((3, 5))
        dist[1] = [0.1, -0.05, 0.001, 0.002, 0.01]  # k3 ≠ 0: FULL_OPENCV
        dist[2, :4] = [0.1, 0.0, 0.0, 0.0]  # OPENCV
        save_rig(tmp_path, rig, format="colmap", image_size=(640, 480), dist=dist)
        models = [
            line.split()[1]
            for line in (tmp_path / "cameras.txt").read_text().splitlines()
            if not line.startswith("#")
        ]
        assert models == ["PINHOLE", "FULL_OPENCV", "OPENCV"]
        loaded = load_rig(tmp_path, dtype=jnp.float64)
        np.testing.assert_array_equal(loaded.dist, dist)
        np.testing.assert_allclose(
            _pixels(loaded),
            np.asarray(cdog_jax.project(rig, jnp.asarray(X), dist=dist)[0]),
            atol=1e-10,
        )


def test_colmap_fisheye_round_trip_and_rational_refused(tmp_path):
    with x64():
        rig = default_rig(num_views=3, dtype=jnp.float64)
        save_rig(tmp_path, rig, format="colmap", image_size=(640, 480), dist=Fisheye(FISHEYE))
        assert "OPENCV_FISHEYE" in (tmp_path / "cameras.txt").read_text()
        loaded = load_rig(tmp_path, dtype=jnp.float64)
    assert isinstance(loaded.dist, Fisheye)
    np.testing.assert_array_equal(loaded.dist.coeffs, FISHEYE)
    text = (tmp_path / "cameras.txt").read_text()
    first = next(line for line in text.splitlines() if not line.startswith("#"))
    fields = first.split()
    rational = " ".join(
        [fields[0], "FULL_OPENCV", *fields[2:8], "0.1", "0", "0", "0", "0", "0.5", "0", "0"]
    )
    (tmp_path / "cameras.txt").write_text(text.replace(first, rational))
    with pytest.raises(
        ValueError,
        match=r"camera 1: FULL_OPENCV with k4, k5, k6 = \[0.5, 0.0, 0.0\] \(the rational model\)",
    ):
        load_rig(tmp_path)


def test_easymocap_prefers_R_and_reads_the_image_size(tmp_path):
    # Rot_01 rounded to 6 digits: within the agreement check, and EasyMocap uses R_01.
    rvec = np.array([0.0, 0.0, 1.5707963267948966])
    rot = np.round(rotation_from_rodrigues(rvec) + 3e-6, 6)
    extri = EASYMOCAP_EXTRI.replace(
        "data: [ 0., -1., 0., 1., 0., 0., 0., 0., 1. ]",
        "data: [ " + ", ".join(repr(float(v)) for v in rot.ravel()) + " ]",
    )
    intri = EASYMOCAP_INTRI + "H_01: 480\nW_01: 640\nH_02: 720\nW_02: 1280\n"
    with x64():
        loaded = load_rig(_easymocap_folder(tmp_path, intri=intri, extri=extri), dtype=jnp.float64)
    np.testing.assert_allclose(
        np.asarray(loaded.rig.R[0]), rotation_from_rodrigues(rvec), atol=1e-15
    )
    assert np.abs(np.asarray(loaded.rig.R[0]) - rot).max() > 1e-6
    np.testing.assert_array_equal(loaded.view_sizes, [[640, 480], [1280, 720]])
    bad = EASYMOCAP_INTRI + "H_01: 480\nW_01: wide\nH_02: 720\nW_02: 1280\n"
    with pytest.raises(
        ValueError,
        match=r"view 0 \(camera '01'\), key \"W_01\": expected a positive integer; got 'wide'",
    ):
        load_rig(_easymocap_folder(tmp_path, intri=bad))
    with pytest.raises(ValueError, match=r"view 1 \(camera '02'\): missing \"H_02\" / \"W_02\""):
        load_rig(_easymocap_folder(tmp_path, intri=EASYMOCAP_INTRI + "H_01: 480\nW_01: 640\n"))


def test_easymocap_writes_the_image_size_and_refuses_fisheye(tmp_path):
    rig = default_rig(num_views=2)
    save_rig(tmp_path / "a", rig, format="easymocap", image_size=[[640, 480], [800, 600]])
    assert "H_01: 600\nW_01: 800\n" in (tmp_path / "a" / "intri.yml").read_text()
    np.testing.assert_array_equal(load_rig(tmp_path / "a").view_sizes, [[640, 480], [800, 600]])
    with pytest.raises(ValueError, match="EasyMocap has no fisheye lens model"):
        save_rig(tmp_path / "b", rig, format="easymocap", dist=Fisheye(FISHEYE[:2]))


def test_anipose_size_is_required_and_sections_sort_as_strings_too(tmp_path):
    rig = default_rig(num_views=12)
    with pytest.raises(
        ValueError,
        match=r"an anipose rig needs image_size: aniposelib cannot load a calibration.toml camera without",
    ):
        save_rig(tmp_path / "c.toml", rig, format="anipose")
    save_rig(tmp_path / "c.toml", rig, format="anipose", image_size=(640, 480))
    sections = re.findall(r"^\[(cam_\d+)\]$", (tmp_path / "c.toml").read_text(), flags=re.M)
    assert (
        sections == sorted(sections)
        and sections[:2] == ["cam_00", "cam_01"]
        and len(sections) == 12
    )
    assert load_rig(tmp_path / "c.toml").names == tuple(f"cam_{m}" for m in range(12))


def test_anipose_cameras_matched_by_name(tmp_path):
    loaded = load_rig(_write(tmp_path / "calibration.toml", ANIPOSE_TOML))
    assert loaded.names == ("left", "right")  # [cam_2] before [cam_10]: numeric order
    swapped = loaded.select(["right", "left"])  # aniposelib's order: "cam_10" < "cam_2"
    assert swapped.names == ("right", "left")
    np.testing.assert_array_equal(np.asarray(swapped.rig.K), np.asarray(loaded.rig.K)[::-1])
    np.testing.assert_array_equal(swapped.dist, loaded.dist[::-1])
    np.testing.assert_array_equal(swapped.view_sizes, loaded.view_sizes[::-1])
    with pytest.raises(
        ValueError, match=r"camera 'centre' is not in this rig; its cameras are \['left', 'right'\]"
    ):
        loaded.select(["centre"])


@pytest.mark.parametrize("fmt", ["anipose", "json", "npz", "colmap", "nerfstudio"])
def test_fisheye_round_trips(tmp_path, fmt):
    with x64():
        rig = default_rig(num_views=3, dtype=jnp.float64)
        # each format's file (a folder for colmap) and whether it needs the image size
        path, sized = {
            "anipose": ("c.toml", True),
            "json": ("r.json", False),
            "npz": ("r.npz", False),
            "colmap": (".", True),
            "nerfstudio": ("transforms.json", True),
        }[fmt]
        size = {"image_size": (640, 480)} if sized else {}
        save_rig(tmp_path / path, rig, format=fmt, dist=Fisheye(FISHEYE), **size)
        loaded = load_rig(tmp_path / path, dtype=jnp.float64)
        assert isinstance(loaded.dist, Fisheye)
        np.testing.assert_array_equal(loaded.dist.coeffs, FISHEYE)
        expected = np.asarray(cdog_jax.project(rig, jnp.asarray(X), dist=Fisheye(FISHEYE))[0])
        np.testing.assert_allclose(_pixels(loaded), expected, atol=1e-9)


NERFSTUDIO = {
    "camera_model": "OPENCV",
    "fl_x": 800.0,
    "fl_y": 790.0,
    "cx": 320.5,
    "cy": 240.5,
    "w": 640,
    "h": 480,
    "k1": 0.1,
    "k2": -0.05,
    "p1": 0.001,
    "p2": 0.002,
    "frames": [
        # camera at (0, 0, 5) looking down -z (OpenGL: the camera looks along its -z).
        {
            "file_path": "images/a.png",
            "transform_matrix": [[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 5], [0, 0, 0, 1]],
        },
        {
            "file_path": "images/b.png",
            "fl_x": 1000.0,
            "fl_y": 1000.0,
            "cx": 640.5,
            "cy": 360.5,
            "w": 1280,
            "h": 720,
            "transform_matrix": [[0, 0, 1, 4], [0, 1, 0, 0], [-1, 0, 0, 0], [0, 0, 0, 1]],
        },
    ],
}


def _nerfstudio_pixel(frame, X):
    """A ray through pixel (u, v) in nerfstudio: direction ((u - cx) / fx, -(v - cy) / fy, -1)
    in OpenGL camera axes, pixel centres at +0.5; inverted here for one point."""
    c2w = np.asarray(frame["transform_matrix"], float)
    Xc = c2w[:3, :3].T @ (X - c2w[:3, 3])  # OpenGL camera coordinates
    x, y = Xc[0] / -Xc[2], -Xc[1] / -Xc[2]
    k1, k2, p1, p2 = (NERFSTUDIO[k] for k in ("k1", "k2", "p1", "p2"))
    r2 = x * x + y * y
    radial = 1 + k1 * r2 + k2 * r2 * r2
    xd = x * radial + 2 * p1 * x * y + p2 * (r2 + 2 * x * x)
    yd = y * radial + p1 * (r2 + 2 * y * y) + 2 * p2 * x * y
    f = {**NERFSTUDIO, **frame}
    return np.array([f["fl_x"] * xd + f["cx"], f["fl_y"] * yd + f["cy"]]) - 0.5


def test_nerfstudio_projects_as_by_hand_and_round_trips(tmp_path):
    path = tmp_path / "transforms.json"
    path.write_text(json.dumps(NERFSTUDIO))
    with x64():
        loaded = load_rig(path, dtype=jnp.float64)
        got = _pixels(loaded)
        expected = np.array([[_nerfstudio_pixel(f, x) for x in X] for f in NERFSTUDIO["frames"]])
        np.testing.assert_allclose(got, expected, atol=1e-9)
        assert loaded.names == ("images/a.png", "images/b.png")
        np.testing.assert_array_equal(loaded.view_sizes, [[640, 480], [1280, 720]])
        (tmp_path / "out").mkdir()
        save_rig(
            tmp_path / "out" / "transforms.json",
            loaded.rig,
            format="nerfstudio",
            image_size=loaded.view_sizes,
            dist=loaded.dist,
            names=loaded.names,
        )
        again = load_rig(tmp_path / "out" / "transforms.json", dtype=jnp.float64)
        np.testing.assert_allclose(_pixels(again), got, atol=1e-9)
    bad = dict(NERFSTUDIO, camera_model="EQUIRECTANGULAR")
    path.write_text(json.dumps(bad))
    with pytest.raises(
        ValueError, match=r"frame 0: camera_model 'EQUIRECTANGULAR' is not supported"
    ):
        load_rig(path)


def test_nerfstudio_transform_must_be_rigid(tmp_path):
    """A 4×4 transform whose last row is not [0, 0, 0, 1] (a projective matrix, or the rows
    of a 3×4 padded with anything) is refused naming the frame."""
    path = tmp_path / "transforms.json"
    frames = [dict(f) for f in NERFSTUDIO["frames"]]
    frames[1]["transform_matrix"] = [*frames[1]["transform_matrix"][:3], [0, 0, 0.5, 1]]
    path.write_text(json.dumps(dict(NERFSTUDIO, frames=frames)))
    with pytest.raises(
        ValueError, match=r"frame 1.*transform_matrix.*last row must be \[0, 0, 0, 1\]"
    ):
        load_rig(path)


def test_float64_without_x64_raises():
    with (
        x64(False),
        pytest.raises(ValueError, match=r"load_rig: dtype=float64 needs 64-bit JAX, which is off"),
    ):
        load_rig("unused.json", dtype=np.float64)
