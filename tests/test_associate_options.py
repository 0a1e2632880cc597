"""`associate` / `associate_batch` options for real data: lens distortion, confidence
weights for the DLT, and a minimum number of views per group."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import cdog_jax
from cdog_jax.geometry import Fisheye, distort_pixels
from cdog_jax.synthetic import default_rig, generate_scene

DIST = np.array([-0.25, 0.08, 1e-3, -5e-4, 0.0])


@pytest.fixture(scope="module")
def scene_and_plain():
    rig = default_rig()
    scene = generate_scene(jax.random.PRNGKey(3), rig, 14, 0.5, capacity=14)
    plain = cdog_jax.associate(rig, scene.xy, scene.mask, sigma=0.5)
    return rig, scene, plain


def _groups(result):
    n = int(result.num_groups)
    return np.asarray(result.groups)[:n]


def test_min_views_keeps_exactly_the_groups_with_enough_views(scene_and_plain):
    rig, scene, plain = scene_and_plain
    out = cdog_jax.associate(rig, scene.xy, scene.mask, sigma=0.5, min_views=4)
    want = _groups(plain)[np.asarray(plain.n_views)[: int(plain.num_groups)] >= 4]
    assert want.shape[0] < int(plain.num_groups)  # the filter removes something here
    np.testing.assert_array_equal(_groups(out), want)
    labels = np.asarray(out.labels)
    for g, row in enumerate(want):  # labels rebuilt for the kept groups only
        for m, slot in enumerate(row):
            if slot >= 0:
                assert labels[m, slot] == g
    assert (labels >= 0).sum() == (want >= 0).sum()


def test_unit_weights_give_the_plain_points(scene_and_plain):
    rig, scene, plain = scene_and_plain
    out = cdog_jax.associate(
        rig, scene.xy, scene.mask, sigma=0.5, weights=np.ones(scene.mask.shape)
    )
    np.testing.assert_array_equal(_groups(out), _groups(plain))
    np.testing.assert_allclose(np.asarray(out.points3d), np.asarray(plain.points3d), atol=1e-4)
    np.testing.assert_allclose(np.asarray(out.bpe), np.asarray(plain.bpe), rtol=1e-3, atol=1e-4)


def test_zero_weight_removes_a_member_from_the_dlt(scene_and_plain):
    rig, scene, plain = scene_and_plain
    groups = _groups(plain)
    g = int(np.argmax(np.asarray(plain.n_views)[: len(groups)]))  # a group of >= 3 views
    members = [(m, s) for m, s in enumerate(groups[g]) if s >= 0]
    assert len(members) >= 3
    weights = np.ones(scene.mask.shape)
    weights[members[0]] = 0.0
    out = cdog_jax.associate(rig, scene.xy, scene.mask, sigma=0.5, weights=weights)
    track = np.zeros((rig.num_views, 2), np.float32)
    observed = np.zeros(rig.num_views, bool)
    for m, s in members[1:]:
        track[m], observed[m] = np.asarray(scene.xy)[m, s], True
    X, ok = cdog_jax.triangulate(rig, jnp.asarray(track), jnp.asarray(observed))
    assert bool(ok)
    np.testing.assert_allclose(np.asarray(out.points3d)[g], np.asarray(X), atol=1e-4)


def test_distorted_detections_with_dist_match_the_pinhole_association(scene_and_plain):
    rig, scene, plain = scene_and_plain
    dist = np.tile(DIST, (rig.num_views, 1)).astype(np.float32)
    xy_lens = distort_pixels(rig.K, jnp.asarray(dist), scene.xy)
    xy_lens = jnp.where(scene.mask[..., None], xy_lens, 0.0)
    # Without the coefficients the lens moves detections by pixels: association degrades.
    shift = np.abs(np.asarray(xy_lens - scene.xy))[np.asarray(scene.mask)].max()
    assert shift > 3.0
    out = cdog_jax.associate(rig, xy_lens, scene.mask, sigma=0.5, dist=dist)
    np.testing.assert_array_equal(_groups(out), _groups(plain))
    np.testing.assert_allclose(np.asarray(out.points3d), np.asarray(plain.points3d), atol=2e-3)


def test_fisheye_detections_with_dist_match_the_pinhole_association(scene_and_plain):
    rig, scene, plain = scene_and_plain
    lens = Fisheye(jnp.asarray(np.tile([0.02, -0.01, 0.0, 0.0], (rig.num_views, 1)), jnp.float32))
    xy_lens = jnp.where(scene.mask[..., None], distort_pixels(rig.K, lens, scene.xy), 0.0)
    assert np.abs(np.asarray(xy_lens - scene.xy))[np.asarray(scene.mask)].max() > 3.0
    out = cdog_jax.associate(rig, xy_lens, scene.mask, sigma=0.5, dist=lens)
    np.testing.assert_array_equal(_groups(out), _groups(plain))
    np.testing.assert_allclose(np.asarray(out.points3d), np.asarray(plain.points3d), atol=2e-3)


def test_batch_options_match_single_scene_calls(scene_and_plain):
    rig, scene, _ = scene_and_plain
    weights = np.random.default_rng(0).uniform(0.2, 1.0, (2, *scene.mask.shape))
    xy, mask = jnp.stack([scene.xy, scene.xy]), jnp.stack([scene.mask, scene.mask])
    batch = cdog_jax.associate_batch(
        rig, xy, mask, sigma=0.5, weights=weights, min_views=3, batch_size=2
    )
    for b in range(2):
        one = cdog_jax.associate(
            rig, scene.xy, scene.mask, sigma=0.5, weights=weights[b], min_views=3
        )
        np.testing.assert_array_equal(np.asarray(batch.groups[b]), np.asarray(one.groups))
        np.testing.assert_allclose(
            np.asarray(batch.points3d[b]), np.asarray(one.points3d), atol=1e-5
        )


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        (dict(min_views=1), r"min_views must be an int >= 2"),
        (dict(min_views=2**40), r"min_views must be at most the number of views, 10"),
        (dict(min_views=11), r"min_views must be at most the number of views, 10 .*; got 11"),
        (dict(dist=np.zeros((3, 5))), r"dist must have shape \(M, 5\) = \(10, 5\)"),
        (dict(dist=np.full((10, 5), np.nan)), r"dist of view 0 has non-finite entries"),
        (dict(weights=np.ones((10, 3))), r"weights must have the shape of mask \(10, 14\)"),
        (
            dict(weights=-np.ones((10, 14))),
            r"weights must be finite and >= 0; got -1.0 at index \(0, 0\)",
        ),
    ],
)
def test_option_errors(scene_and_plain, kwargs, message):
    rig, scene, _ = scene_and_plain
    with pytest.raises(ValueError, match=message):
        cdog_jax.associate(rig, scene.xy, scene.mask, sigma=0.5, **kwargs)


def test_rig_checks_fewer_than_two_views_and_non_finite_K():
    rig = default_rig()
    with pytest.raises(ValueError, match=r"the rig must have at least 2 views; got 1"):
        cdog_jax.associate(rig.select([0]), np.zeros((1, 3, 2), np.float32), np.ones((1, 3), bool))
    K = np.array(rig.K)
    K[3, 0, 0] = np.inf
    with pytest.raises(ValueError, match=r"K of view 3 has non-finite entries"):
        cdog_jax.rig_from_arrays(K, rig.R, rig.t)
