"""Rigs from and to other libraries' objects without those libraries: hand-built stand-ins
with the attributes of aniposelib's ``Camera``/``CameraGroup`` and pycolmap's
``Reconstruction``, and plain OpenCV arrays. Each is checked against a projection written
here in the library's own convention."""

import jax.numpy as jnp
import numpy as np
import pytest
from helpers import x64

import cdog_jax
from cdog_jax.geometry import Fisheye
from cdog_jax.io import (
    opencv_from_rig,
    quaternion_from_rotation,
    rig_from_aniposelib,
    rig_from_opencv,
    rig_from_pycolmap,
    rodrigues_from_rotation,
    rotation_from_quaternion,
    rotation_from_rodrigues,
)

X = np.array([[0.3, -0.2, 1.5], [-0.4, 0.1, 0.7], [0.0, 0.0, 0.0]])
K = np.array(
    [
        [[800.0, 0.0, 320.0], [0.0, 790.0, 240.0], [0.0, 0.0, 1.0]],
        [[1000.0, 0.0, 640.0], [0.0, 1000.0, 360.0], [0.0, 0.0, 1.0]],
    ]
)
RVEC = np.array([[0.0, 0.5, 0.0], [0.3, -0.2, 0.1]])
TVEC = np.array([[0.1, -0.2, 4.0], [0.5, 0.1, 3.0]])
DIST = np.array([[0.1, -0.05, 0.001, 0.002, 0.0], [-0.2, 0.03, 0.0, 0.0, 0.01]])


def _skew(v):
    return np.array([[0.0, -v[2], v[1]], [v[2], 0.0, -v[0]], [-v[1], v[0], 0.0]])


def _rotation(rvec):
    """exp([r]_x) by its power series, independent of the library."""
    out, term = np.eye(3), np.eye(3)
    for k in range(1, 40):
        term = term @ _skew(rvec) / k
        out = out + term
    return out


def _opencv_pixels(K, dist, rvec, tvec, X):
    """``cv2.projectPoints`` written out: OpenCV's 5-coefficient model, float64."""
    Xc = X @ _rotation(rvec).T + tvec
    x, y = Xc[:, 0] / Xc[:, 2], Xc[:, 1] / Xc[:, 2]
    k1, k2, p1, p2, k3 = dist
    r2 = x * x + y * y
    radial = 1 + k1 * r2 + k2 * r2**2 + k3 * r2**3
    xd = x * radial + 2 * p1 * x * y + p2 * (r2 + 2 * x * x)
    yd = y * radial + p1 * (r2 + 2 * y * y) + 2 * p2 * x * y
    return np.stack([K[0, 0] * xd + K[0, 1] * yd + K[0, 2], K[1, 1] * yd + K[1, 2]], -1)


def _ours(rig_file):
    xy, ok = cdog_jax.project(rig_file.rig, jnp.asarray(X), dist=rig_file.dist)
    assert np.asarray(ok).all()
    return np.asarray(xy)


# aniposelib stand-ins ---------------------------------------------------------------------


class Camera:
    """aniposelib's ``Camera`` getters (aniposelib.cameras.Camera)."""

    def __init__(self, matrix, dist, size, rvec, tvec, name):
        self.matrix, self.dist, self.size = np.asarray(matrix), np.asarray(dist), size
        self.rvec, self.tvec, self.name = np.asarray(rvec), np.asarray(tvec), name

    def get_camera_matrix(self):
        return self.matrix

    def get_distortions(self):
        return self.dist

    def get_rotation(self):
        return self.rvec

    def get_translation(self):
        return self.tvec

    def get_size(self):
        return self.size

    def get_name(self):
        return self.name


class FisheyeCamera(Camera):
    pass


class CameraGroup:
    def __init__(self, cameras):
        self.cameras = cameras


def test_rig_from_aniposelib_projects_as_opencv():
    group = CameraGroup(
        [Camera(K[m], DIST[m], [640 + m, 480], RVEC[m], TVEC[m], f"c{m}") for m in range(2)]
    )
    with x64():
        loaded = rig_from_aniposelib(group, dtype=jnp.float64)
        ours = _ours(loaded)
    for m in range(2):
        np.testing.assert_allclose(
            ours[m], _opencv_pixels(K[m], DIST[m], RVEC[m], TVEC[m], X), atol=1e-9
        )
    assert loaded.names == ("c0", "c1")
    np.testing.assert_array_equal(loaded.view_sizes, [[640, 480], [641, 480]])
    np.testing.assert_array_equal(loaded.dist, DIST)


def test_rig_from_aniposelib_fisheye_and_refusals():
    fish = [
        FisheyeCamera(K[m], [0.05, -0.01, 0.0, 0.0], [640, 480], RVEC[m], TVEC[m], f"c{m}")
        for m in range(2)
    ]
    loaded = rig_from_aniposelib(CameraGroup(fish))
    assert isinstance(loaded.dist, Fisheye)
    np.testing.assert_array_equal(loaded.dist.coeffs, [[0.05, -0.01, 0.0, 0.0]] * 2)
    with pytest.raises(ValueError, match=r"cameras \[0\] are FisheyeCamera and the others are not"):
        rig_from_aniposelib(
            CameraGroup([fish[0], Camera(K[1], DIST[1], [640, 480], RVEC[1], TVEC[1], "c1")])
        )
    with pytest.raises(ValueError, match=r"camera 1 \('c1'\) has no size and others have one"):
        rig_from_aniposelib(
            CameraGroup([fish[0], FisheyeCamera(K[1], [0.0] * 4, None, RVEC[1], TVEC[1], "c1")])
        )
    bad = Camera(K[1], DIST[1], [640, 480], [0.1, 0.2], TVEC[1], "c1")
    with pytest.raises(ValueError, match=r"rvec\[1\]: expected shape \(3,\); got \(2,\)"):
        rig_from_aniposelib(
            CameraGroup([Camera(K[0], DIST[0], [640, 480], RVEC[0], TVEC[0], "c0"), bad])
        )


# pycolmap stand-ins -----------------------------------------------------------------------


class Rigid3d:
    def __init__(self, R, t):
        self._Rt = np.concatenate([R, t[:, None]], axis=1)

    def matrix(self):
        return self._Rt


class Image:
    def __init__(self, camera_id, name, R, t, posed=True):
        self.camera_id, self.name, self._pose, self._posed = camera_id, name, Rigid3d(R, t), posed

    def cam_from_world(self):  # a method in pycolmap ≥ 3.12, an attribute before
        return self._pose

    def has_pose(self):
        return self._posed


class ColmapCamera:
    def __init__(self, model_name, params, width, height):
        self.model_name, self.params, self.width, self.height = (
            model_name,
            np.asarray(params),
            width,
            height,
        )


class Reconstruction:
    def __init__(self, cameras, images):
        self.cameras, self.images = cameras, images


def test_rig_from_pycolmap_shifts_pixel_centres_and_reads_models():
    R = [_rotation(r) for r in RVEC]
    # FULL_OPENCV with k4 = k5 = k6 = 0 is OpenCV's 5-coefficient model.
    cameras = {
        7: ColmapCamera("OPENCV", [800.0, 790.0, 320.5, 240.5, *DIST[0, :4]], 640, 480),
        3: ColmapCamera(
            "FULL_OPENCV", [1000.0, 1000.0, 640.5, 360.5, *DIST[1], 0.0, 0.0, 0.0], 1280, 720
        ),
    }
    images = {
        20: Image(3, "b.png", R[1], TVEC[1]),
        5: Image(7, "a.png", R[0], TVEC[0]),
        9: Image(7, "x.png", R[0], TVEC[0], posed=False),
    }
    with x64():
        loaded = rig_from_pycolmap(Reconstruction(cameras, images), dtype=jnp.float64)
        ours = _ours(loaded)
    assert loaded.names == ("a.png", "b.png")  # ascending image_id, unposed images skipped
    for m in range(2):
        np.testing.assert_allclose(
            ours[m], _opencv_pixels(K[m], DIST[m], RVEC[m], TVEC[m], X), atol=1e-9
        )
    np.testing.assert_array_equal(loaded.view_sizes, [[640, 480], [1280, 720]])
    cameras[3] = ColmapCamera(
        "FULL_OPENCV", [1000.0, 1000.0, 640.5, 360.5, *DIST[1], 0.1, 0.0, 0.0], 1280, 720
    )
    with pytest.raises(
        ValueError,
        match=r"image 20 \('b.png'\), camera 3: FULL_OPENCV with k4, k5, k6 = \[0.1, 0.0, 0.0\]",
    ):
        rig_from_pycolmap(Reconstruction(cameras, images))
    cameras[3] = ColmapCamera("FOV", [1000.0, 1000.0, 640.5, 360.5, 0.1], 1280, 720)
    with pytest.raises(ValueError, match=r"unsupported camera model 'FOV'"):
        rig_from_pycolmap(Reconstruction(cameras, images))


# OpenCV arrays and rotations --------------------------------------------------------------


def test_opencv_arrays_round_trip_and_project_as_opencv():
    with x64():
        loaded = rig_from_opencv(
            list(K),
            list(DIST),
            [r[:, None] for r in RVEC],
            list(TVEC),
            image_size=(640, 480),
            names=["a", "b"],
            dtype=jnp.float64,
        )
        for m in range(2):
            np.testing.assert_allclose(
                _ours(loaded)[m], _opencv_pixels(K[m], DIST[m], RVEC[m], TVEC[m], X), atol=1e-9
            )
        back = opencv_from_rig(loaded.rig, dist=loaded.dist, image_size=loaded.image_size)
    np.testing.assert_allclose(back.rvec, RVEC, atol=1e-15)
    np.testing.assert_array_equal(back.tvec, TVEC)
    np.testing.assert_array_equal(back.K, K)
    np.testing.assert_array_equal(back.dist, DIST)
    assert back.image_size.tolist() == [[640, 480]] * 2 and not back.fisheye
    fish = rig_from_opencv(K, [[0.1, 0.0, 0.0, 0.0]] * 2, RVEC, TVEC, fisheye=True)
    assert isinstance(fish.dist, Fisheye) and opencv_from_rig(fish.rig, dist=fish.dist).fisheye
    with pytest.raises(
        ValueError, match=r"dist\[1\]: expected 4 or 5 OpenCV distortion coefficients.*got 6"
    ):
        rig_from_opencv(K, [DIST[0], np.zeros(6)], RVEC, TVEC)
    with pytest.raises(
        ValueError, match=r"tvec: expected 2 entries \(one per camera, M=2 from K\); got 1"
    ):
        rig_from_opencv(K, None, RVEC, TVEC[:1])


def test_rotation_helpers_are_public_and_exact():
    for r in RVEC:
        R = rotation_from_rodrigues(r)
        np.testing.assert_allclose(R, _rotation(r), atol=1e-15)
        np.testing.assert_allclose(rodrigues_from_rotation(R), r, atol=1e-15)
        np.testing.assert_allclose(
            rotation_from_quaternion(quaternion_from_rotation(R)), R, atol=1e-15
        )
