"""Rig.describe / describe_rig: the numbers match NumPy, and wrong rigs are flagged."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from helpers import look_at

from cdog_jax.geometry import Rig, RigDescription, describe_rig, distort_pixels
from cdog_jax.synthetic import DEFAULT_BOX, IMAGE_SIZE, default_rig, generate_scene
from cdog_jax.synthetic._rig import look_at_rotation, negate_intrinsics


@pytest.fixture(scope="module")
def rig():
    return default_rig()


@pytest.fixture(scope="module")
def scene(rig):
    return generate_scene(jax.random.PRNGKey(0), rig, 30, 1.0, capacity=30)


def _camera_to_world(rig: Rig) -> Rig:
    """The classic mistake: R and t of camera→world (Rᵀ and the centre) passed as world→camera."""
    return Rig(rig.K, jnp.swapaxes(rig.R, -1, -2), rig.centers)


def test_default_rig_with_scene_has_no_warnings(rig, scene):
    desc = describe_rig(rig, xy=scene.xy, mask=scene.mask, image_size=IMAGE_SIZE)
    assert desc.warnings == []
    assert desc.axes_point_in_front.all()
    lo, hi = np.asarray(DEFAULT_BOX)
    assert np.all(desc.centroid >= lo) and np.all(desc.centroid <= hi), desc.centroid
    assert np.all(desc.centroid_angle_deg < 20.0)
    text = desc.format()
    assert text == str(desc) and "No warnings." in text and "WARNING" not in text
    assert len(text.splitlines()) >= rig.num_views + 4
    assert describe_rig(rig).warnings == []  # without detections
    # K[2,2] = -1 (OpenMVG style) in two views: same pixels, same verdict, same centroid.
    neg = describe_rig(
        negate_intrinsics(rig, [0, 3]), xy=scene.xy, mask=scene.mask, image_size=IMAGE_SIZE
    )
    assert neg.warnings == []
    np.testing.assert_allclose(neg.centroid, desc.centroid, atol=1e-6)


def test_numbers_match_numpy(rig):
    rig = negate_intrinsics(rig, [0, 3])  # K[2,2] = -1 in two views changes nothing
    desc = describe_rig(rig, names=[f"cam{m}" for m in range(rig.num_views)])
    K, R, t = (np.asarray(a, np.float64) for a in (rig.K, rig.R, rig.t))
    centers = np.stack([-R[m].T @ t[m] for m in range(len(K))])
    np.testing.assert_allclose(desc.centers, centers, atol=1e-5)
    np.testing.assert_allclose(desc.view_dirs, R[:, 2], atol=1e-6)
    np.testing.assert_allclose(np.linalg.norm(desc.view_dirs, axis=1), 1.0, atol=1e-6)
    Kn = K / K[:, 2:3, 2:3]
    np.testing.assert_allclose(desc.focal_px, np.stack([Kn[:, 0, 0], Kn[:, 1, 1]], 1), rtol=1e-6)
    np.testing.assert_allclose(desc.principal_px, Kn[:, :2, 2], rtol=1e-6)
    assert (desc.focal_px > 1000).all()
    d = np.array([[np.linalg.norm(a - b) for b in centers] for a in centers])
    pairs = d[np.triu_indices(len(K), 1)]
    np.testing.assert_allclose(
        [desc.baseline_min, desc.baseline_median, desc.baseline_max],
        [pairs.min(), np.median(pairs), pairs.max()],
        rtol=1e-5,
    )
    i, j = desc.closest_pair
    assert d[i, j] == pytest.approx(pairs.min(), rel=1e-5)
    assert desc.names[0] == "cam0" and "cam9" in str(desc)


def test_axes_point_is_the_common_target():
    target = np.array([0.2, -0.1, 0.3])
    centers = np.array([[2.0, 0.0, 2.0], [0.0, 2.5, 1.5], [-2.0, -1.0, 2.5], [0.5, -2.0, 3.0]])
    R = np.stack([look_at_rotation(c, target) for c in centers])
    t = -np.einsum("mij,mj->mi", R, centers)
    K = np.tile(np.array([[800.0, 0, 320], [0, 800, 240], [0, 0, 1]]), (4, 1, 1))
    desc = describe_rig(Rig(*(jnp.asarray(a, jnp.float32) for a in (K, R, t))))
    np.testing.assert_allclose(desc.axes_point, target, atol=1e-4)
    assert desc.axes_point_in_front.all() and desc.warnings == []


def test_camera_to_world_rig_is_flagged(rig, scene):
    bad = _camera_to_world(rig)
    for kwargs in ({"xy": scene.xy, "mask": scene.mask, "image_size": IMAGE_SIZE}, {}):
        desc = describe_rig(bad, **kwargs)
        pointing = [
            w for w in desc.warnings if "points away" in w or "outside its" in w or "converge" in w
        ]
        assert len(pointing) >= 2, desc.warnings
        assert any("camera→world" in w for w in desc.warnings), desc.warnings
    assert "WARNINGS" in describe_rig(bad, xy=scene.xy, mask=scene.mask).format()


def test_identical_cameras_are_flagged(rig, scene):
    K, R, t = (a.at[4].set(a[2]) for a in (rig.K, rig.R, rig.t))
    desc = describe_rig(Rig(K, R, t), xy=scene.xy, mask=scene.mask)
    assert any("views 2 and 4 have the same centre" in w for w in desc.warnings), desc.warnings
    assert desc.baseline_min == 0.0 and desc.closest_pair == (2, 4)


def test_padding_is_ignored_and_distortion_is_undone(rig, scene):
    base = describe_rig(rig, xy=scene.xy, mask=scene.mask)
    garbage = jnp.where(scene.mask[..., None], scene.xy, 1e7)
    np.testing.assert_allclose(
        describe_rig(rig, xy=garbage, mask=scene.mask).centroid, base.centroid, atol=1e-9
    )
    # Strong barrel distortion for the default rig's narrow field of view (r ≤ 0.31 at the
    # corners): up to ~50 px, so that the naive centroid moves.
    dist = jnp.tile(jnp.asarray([[-2.0, 5.0, 2e-3, 1e-3, 0.0]], jnp.float32), (rig.num_views, 1))
    distorted = distort_pixels(rig.K, dist, scene.xy)
    undone = describe_rig(rig, xy=distorted, mask=scene.mask, dist=dist)
    np.testing.assert_allclose(undone.centroid, base.centroid, atol=1e-3)
    naive = describe_rig(rig, xy=distorted, mask=scene.mask)
    assert np.linalg.norm(naive.centroid - base.centroid) > 1e-2


def test_bad_input_raises(rig, scene):
    with pytest.raises(ValueError, match="names must hold M=10"):
        describe_rig(rig, names=["a"])
    with pytest.raises(ValueError, match="xy must have shape"):
        describe_rig(rig, xy=scene.xy[:3])
    with pytest.raises(ValueError, match="image_size"):
        describe_rig(rig, image_size=(640, 480, 3))
    assert isinstance(
        describe_rig(rig.select([0])), RigDescription
    )  # one view: no baselines, no error


def test_near_zero_baseline_is_warned_about():
    def rig_at(centers):
        K, R, t = [], [], []
        for c in centers:
            Rm, tm = look_at(c)
            K.append([[800.0, 0.0, 320.0], [0.0, 800.0, 240.0], [0.0, 0.0, 1.0]])
            R.append(Rm)
            t.append(tm)
        return Rig(*(jnp.asarray(np.array(a), jnp.float32) for a in (K, R, t)))

    desc = describe_rig(rig_at([(3.0, 0.0, 1.0), (3.0, 1e-3, 1.0), (0.0, 3.0, 1.0)]))
    short = [w for w in desc.warnings if "views 0 and 1 are only 0.001 apart" in w]
    assert len(short) == 1 and "0.0181°" in short[0], desc.warnings
    assert len(desc.warnings) == 1
    healthy = describe_rig(
        rig_at([(3.0, 0.0, 1.0), (3.0, 0.3, 1.0), (0.0, 3.0, 1.0)])
    )  # 5.4° at the origin
    assert healthy.warnings == []
