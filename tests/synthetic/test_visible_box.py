"""Scene boxes for user rigs: the image size implied by K and the box seen by ≥ 2 views."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from helpers import look_at

from cdog_jax.geometry import rig_from_arrays
from cdog_jax.synthetic import (
    DEFAULT_BOX,
    IMAGE_SIZE,
    default_rig,
    generate_scene,
    visible_box,
)
from cdog_jax.synthetic._box import _seen, intrinsics_image_size
from cdog_jax.synthetic._rig import negate_intrinsics

LO, HI = (np.asarray(c) for c in DEFAULT_BOX)


@pytest.fixture(scope="module")
def box():
    return visible_box(default_rig(), IMAGE_SIZE)


def test_intrinsics_image_size_of_default_rig():
    rig = default_rig()
    assert intrinsics_image_size(rig.K) == IMAGE_SIZE
    assert intrinsics_image_size(negate_intrinsics(rig, [0, 4, 7]).K) == IMAGE_SIZE
    K = np.array([[1000.0, 0.0, 959.5], [0.0, 1000.0, 539.5], [0.0, 0.0, 1.0]])
    assert intrinsics_image_size(-K) == (1920, 1080)
    assert intrinsics_image_size(K, multiple=1) == (1919, 1079)
    with pytest.raises(ValueError, match="image size"):
        intrinsics_image_size(np.array([[800.0, 0.0, -300.0], [0.0, 800.0, 2.0], [0.0, 0.0, 1.0]]))


def test_box_of_default_rig_covers_default_box(box):
    assert box.shape == (2, 3) and box.dtype == np.float64
    assert np.all(box[0] < box[1])
    # The centre region of DEFAULT_BOX (its middle half on every axis) lies inside the box.
    centre_lo, centre_hi = LO + 0.25 * (HI - LO), HI - 0.25 * (HI - LO)
    assert np.all(box[0] <= centre_lo) and np.all(centre_hi <= box[1])
    # Most of DEFAULT_BOX's volume is inside, and the box is not absurdly large.
    overlap = np.prod(np.clip(np.minimum(box[1], HI) - np.maximum(box[0], LO), 0.0, None))
    assert overlap >= 0.8 * np.prod(HI - LO)
    assert np.all(box[1] - box[0] < 10.0)


def test_box_is_mostly_seen_by_two_views(box):
    X = np.random.default_rng(3).uniform(box[0], box[1], size=(20000, 3))
    assert len(_seen(default_rig(), X, IMAGE_SIZE, 2)) > 0.35 * len(X)


def test_generate_scene_fills_the_box(box):
    rig = default_rig()
    for seed in range(3):
        scene = generate_scene(jax.random.PRNGKey(seed), rig, 50, 1.0, capacity=50, box=box)
        assert int(scene.num_points) == 50


def test_deterministic_and_seed_dependent(box):
    rig = default_rig()
    np.testing.assert_array_equal(visible_box(rig, IMAGE_SIZE), box)
    other = visible_box(rig, IMAGE_SIZE, seed=1)
    assert not np.array_equal(other, box)
    np.testing.assert_allclose(other, box, atol=0.15)


def test_negated_intrinsics_give_the_same_box(box):
    rig = negate_intrinsics(default_rig(), np.arange(10))
    np.testing.assert_allclose(visible_box(rig, IMAGE_SIZE), box, atol=1e-6)


def test_more_views_required_shrinks_the_box(box):
    box3 = visible_box(default_rig(), IMAGE_SIZE, min_views=3)
    assert np.all(box3[0] >= box[0] - 0.05) and np.all(box3[1] <= box[1] + 0.05)


def test_cameras_back_to_back_raise():
    K = np.array([[800.0, 0.0, 320.0], [0.0, 800.0, 240.0], [0.0, 0.0, 1.0]])
    R0, t0 = look_at((0.0, 0.0, 0.0), target=(1.0, 0.0, 0.0))
    R1, t1 = look_at((0.0, 0.0, 0.0), target=(-1.0, 0.0, 0.0))
    R2, t2 = look_at((0.0, 0.0, 0.5), target=(0.0, 3.0, 0.5))
    rig = rig_from_arrays(np.stack([K, K, K]), np.stack([R0, R1, R2]), np.stack([t0, t1, t2]))
    with pytest.raises(ValueError, match="common region"):
        visible_box(rig, IMAGE_SIZE)
    # One view is always visible somewhere.
    assert visible_box(rig, IMAGE_SIZE, min_views=1).shape == (2, 3)


def test_bad_arguments():
    rig = default_rig(num_views=3)
    with pytest.raises(ValueError, match="min_views"):
        visible_box(rig, IMAGE_SIZE, min_views=4)
    with pytest.raises(ValueError, match="quantile"):
        visible_box(rig, IMAGE_SIZE, quantile=0.5)
    batched = jax.tree_util.tree_map(lambda a: jnp.stack([a, a]), rig)
    with pytest.raises(ValueError, match="one rig"):
        visible_box(batched, IMAGE_SIZE)
