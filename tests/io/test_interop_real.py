"""Round trips with the real libraries (the ``[interop]`` extra; skipped when absent):
aniposelib's ``CameraGroup`` (in memory and through its own ``dump``/``load``), pycolmap's
``Reconstruction`` and ``cv2.projectPoints`` agree with this library's projection."""

import jax.numpy as jnp
import numpy as np
import pytest
from helpers import x64

import cdog_jax
from cdog_jax.geometry import Fisheye
from cdog_jax.io import (
    aniposelib_from_rig,
    load_rig,
    opencv_from_rig,
    pycolmap_from_rig,
    rig_from_aniposelib,
    rig_from_pycolmap,
    save_rig,
)
from cdog_jax.synthetic import default_rig

X = np.random.default_rng(3).uniform(-0.4, 0.4, (25, 3))
DIST = np.tile([-0.2, 0.05, 1e-3, -2e-3, 0.01], (12, 1))
PX = 1e-9  # float64 agreement, pixels


def _ours(rig, dist):
    return np.asarray(cdog_jax.project(rig, jnp.asarray(X), dist=dist)[0])


def test_opencv_project_points():
    cv2 = pytest.importorskip("cv2")
    with x64():
        rig = default_rig(num_views=4, dtype=jnp.float64)
        cams = opencv_from_rig(rig, dist=DIST[:4])
        ours = _ours(rig, DIST[:4])
    for m in range(4):
        ref = cv2.projectPoints(X, cams.rvec[m], cams.tvec[m], cams.K[m], cams.dist[m])[0][:, 0]
        assert np.abs(ref - ours[m]).max() < PX


def test_aniposelib_in_memory_and_through_its_files(tmp_path):
    aniposelib = pytest.importorskip("aniposelib.cameras")
    with x64():
        rig = default_rig(num_views=12, dtype=jnp.float64)
        group = aniposelib_from_rig(rig, image_size=(640, 480), dist=DIST)
        assert np.abs(group.project(X) - _ours(rig, DIST)).max() < PX
        back = rig_from_aniposelib(group, dtype=jnp.float64)
        assert np.abs(_ours(back.rig, back.dist) - _ours(rig, DIST)).max() < PX
        # aniposelib loads our file (it needs "size"), in our order despite 12 cameras.
        save_rig(
            tmp_path / "calibration.toml", rig, format="anipose", image_size=(640, 480), dist=DIST
        )
        loaded = aniposelib.CameraGroup.load(str(tmp_path / "calibration.toml"))
        assert loaded.get_names() == [f"cam_{m}" for m in range(12)]
        assert np.abs(loaded.project(X) - _ours(rig, DIST)).max() < PX
        # A file aniposelib wrote: its load orders cam_10 before cam_2; names match them up.
        group.dump(str(tmp_path / "theirs.toml"))
        theirs = aniposelib.CameraGroup.load(str(tmp_path / "theirs.toml"))
        ours = load_rig(tmp_path / "theirs.toml", dtype=jnp.float64)
        assert theirs.get_names() != list(ours.names)
        matched = ours.select(theirs.get_names())
        assert np.abs(theirs.project(X) - _ours(matched.rig, matched.dist)).max() < PX


def test_aniposelib_fisheye():
    pytest.importorskip("aniposelib.cameras")
    pytest.importorskip("cv2")
    lens = Fisheye(np.tile([0.05, -0.01, 0.002, 0.0], (3, 1)))
    with x64():
        rig = default_rig(num_views=3, dtype=jnp.float64)
        group = aniposelib_from_rig(rig, image_size=(640, 480), dist=lens)
        assert type(group.cameras[0]).__name__ == "FisheyeCamera"
        assert np.abs(group.project(X) - _ours(rig, lens)).max() < PX
        back = rig_from_aniposelib(group)
    assert isinstance(back.dist, Fisheye)


def test_pycolmap_reconstruction():
    pycolmap = pytest.importorskip("pycolmap")
    with x64():
        rig = default_rig(num_views=3, dtype=jnp.float64)
        dist = DIST[:3].copy()
        dist[0, 4] = 0.0  # one OPENCV camera, two FULL_OPENCV
        reconstruction = pycolmap_from_rig(
            rig, image_size=(640, 480), dist=dist, names=["a", "b", "c"]
        )
        assert isinstance(reconstruction, pycolmap.Reconstruction)
        ours = _ours(rig, dist)
        for m, image_id in enumerate(sorted(reconstruction.images)):
            image = reconstruction.images[image_id]
            pose = (
                image.cam_from_world() if callable(image.cam_from_world) else image.cam_from_world
            )
            camera = reconstruction.cameras[image.camera_id]
            theirs = (
                np.array([camera.img_from_cam(pose * x) for x in X]) - 0.5
            )  # COLMAP's pixel centres
            assert np.abs(theirs - ours[m]).max() < PX
        back = rig_from_pycolmap(reconstruction, dtype=jnp.float64)
        assert back.names == ("a", "b", "c")
        assert np.abs(_ours(back.rig, back.dist) - ours).max() < PX
