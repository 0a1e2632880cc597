"""End-to-end properties of the jitted pipeline (small scenes; the oracle comparison is in
test_pipeline_vs_oracle.py)."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from helpers import purity, random_scene, ring_rig, x64

import cdog_jax
from cdog_jax import Config, Status, associate, associate_batch, associate_traced
from cdog_jax._runtime.stored_programs import loaded_programs

PRESETS = {"paper": Config.paper(), "reference": Config.reference(), "extended": Config.extended()}
RIG = ring_rig(5)
M, P = 5, 12


def _group_sets(res):
    labels = np.asarray(res.labels)
    return sorted(tuple(sorted(zip(*np.nonzero(labels == g)))) for g in range(int(res.num_groups)))


@pytest.mark.parametrize("preset", PRESETS)
def test_garbage_in_padded_slots_changes_nothing(preset):
    xy, mask, _, _ = random_scene(RIG, 8, P, sigma=1.0, seed=3)
    noisy = xy.copy()
    noisy[~mask] = np.random.default_rng(0).uniform(-1e4, 1e4, (int((~mask).sum()), 2))
    noisy[~mask][:3] = np.nan  # even NaN where masked
    a = associate(RIG, xy, mask, method=PRESETS[preset], sigma=1.0)
    b = associate(RIG, noisy, mask, method=PRESETS[preset], sigma=1.0)
    for fa, fb in zip(jax.tree.leaves(a), jax.tree.leaves(b)):
        assert np.array_equal(np.asarray(fa), np.asarray(fb))


@pytest.mark.parametrize("preset", PRESETS)
def test_permuting_slots_permutes_labels(preset):
    xy, mask, _, _ = random_scene(RIG, 9, P, sigma=0.5, seed=4)
    rng = np.random.default_rng(1)
    perms = [rng.permutation(P) for _ in range(M)]
    xy_p = np.stack([xy[m][perms[m]] for m in range(M)])
    mask_p = np.stack([mask[m][perms[m]] for m in range(M)])
    a = associate(RIG, xy, mask, method=PRESETS[preset], sigma=0.5)
    b = associate(RIG, xy_p, mask_p, method=PRESETS[preset], sigma=0.5)
    inverse = [np.argsort(p) for p in perms]
    back = {(m, int(inverse[m][i])) for m in range(M) for i in range(P)}
    assert back  # the permutation is a bijection
    sets_b = sorted(tuple(sorted((m, int(perms[m][i])) for m, i in grp)) for grp in _group_sets(b))
    assert sets_b == _group_sets(a)


def test_batch_equals_loop_shared_and_per_scene_rig():
    """Four views, as methods/test_conformance.py: the shared-rig batch (one chunk of 4) and
    the single scenes run the programs that test compiles; the per-scene rigs run in chunks
    of 2, the last padded."""
    rig = ring_rig(4)
    scenes = [
        random_scene(rig, n, P, sigma=s, seed=10 + n) for n, s in [(3, 0.0), (8, 1.0), (12, 2.0)]
    ]
    xy = np.stack([s[0] for s in scenes])
    mask = np.stack([s[1] for s in scenes])
    sigmas = jnp.asarray([0.0, 1.0, 2.0], jnp.float32)
    batched = associate_batch(rig, xy, mask, sigma=sigmas)
    rigs = jax.tree.map(lambda a: jnp.stack([a] * 3), rig)
    per_scene = associate_batch(rigs, xy, mask, sigma=sigmas, batch_size=2)
    for b in range(3):
        single = associate(rig, xy[b], mask[b], sigma=float(sigmas[b]))
        for f_single, f_batch, f_rigs in zip(
            jax.tree.leaves(single), jax.tree.leaves(batched), jax.tree.leaves(per_scene)
        ):
            assert np.allclose(np.asarray(f_single), np.asarray(f_batch)[b], atol=1e-4)
            assert np.allclose(np.asarray(f_single), np.asarray(f_rigs)[b], atol=1e-4)


def test_jit_equals_eager():
    xy, mask, _, _ = random_scene(RIG, 4, 5, sigma=1.0, seed=5)
    cfg = Config.paper()
    thresholds = cfg.thresholds(1.0)
    jitted = associate(RIG, xy, mask, method=cfg, sigma=1.0)
    with jax.disable_jit():
        eager = associate_traced(
            RIG, jnp.asarray(xy, jnp.float32), jnp.asarray(mask), thresholds, cfg
        )
    for fa, fb in zip(jax.tree.leaves(jitted), jax.tree.leaves(eager)):
        assert np.allclose(np.asarray(fa), np.asarray(fb), atol=1e-4)


def test_negative_k22_gives_the_same_association():
    rig_neg = ring_rig(5, negate=(1, 4))
    assert float(rig_neg.K[1, 2, 2]) == -1.0
    xy, mask, _, _ = random_scene(RIG, 10, P, sigma=0.5, seed=6)
    a = associate(RIG, xy, mask, sigma=0.5)
    b = associate(rig_neg, xy, mask, sigma=0.5)
    assert np.array_equal(np.asarray(a.labels), np.asarray(b.labels))
    assert np.allclose(np.asarray(a.points3d), np.asarray(b.points3d), atol=1e-4)


@pytest.mark.parametrize("preset", PRESETS)
def test_noise_free_scenes_are_associated_exactly(preset):
    # With exact projections every true pair has epipolar distance ~1e-3 px, far below τ;
    # on a 5-camera ring at these densities every group must be pure and complete.
    for seed, n in enumerate([1, 4, 10]):
        xy, mask, inst, _ = random_scene(RIG, n, P, sigma=0.0, seed=20 + seed)
        res = associate(RIG, xy, mask, method=PRESETS[preset], sigma=0.0)
        groups, pure, unassigned = purity(res.labels, inst, mask)
        assert (groups, pure, unassigned) == (n, n, 0)


def test_float64_pipeline():
    with x64():
        rig = ring_rig(5, dtype=np.float64)
        xy, mask, inst, X = random_scene(rig, 10, P, sigma=0.0, seed=7)
        res = associate(rig, xy, mask, sigma=0.0)
        assert res.points3d.dtype == jnp.float64
        groups, pure, unassigned = purity(res.labels, inst, mask)
        assert (groups, pure, unassigned) == (10, 10, 0)
        labels = np.asarray(res.labels)
        for g in range(int(res.num_groups)):
            truth = X[inst[labels == g][0]]
            assert np.abs(np.asarray(res.points3d[g]) - truth).max() < 1e-9


def test_refinement_lowers_reprojection_error():
    xy, mask, _, _ = random_scene(RIG, 10, P, sigma=2.0, seed=8)
    plain = associate(RIG, xy, mask, sigma=2.0, method=Config.paper(bpe_filter=False))
    refined = associate(
        RIG, xy, mask, sigma=2.0, method=Config.paper(bpe_filter=False, refine=True)
    )
    assert np.array_equal(np.asarray(plain.labels), np.asarray(refined.labels))
    n = int(plain.num_groups)
    assert n > 0
    b0, b1 = np.asarray(plain.bpe)[:n], np.asarray(refined.bpe)[:n]
    assert np.all(b1 <= b0 + 1e-4) and b1.mean() < b0.mean()


def test_sigma_auto_is_reported_and_reasonable():
    xy, mask, _, _ = random_scene(RIG, 12, P, sigma=2.0, seed=9)
    res = associate(RIG, xy, mask, sigma="auto")
    assert 1.4 < float(res.sigma_px) < 2.8
    assert float(res.tau_px) == pytest.approx(
        max(2 * np.sqrt(2) * float(res.sigma_px), 1.0), rel=1e-5
    )


def test_sigma_fallback_is_flagged():
    # One detection in each of two views, of different points: too little evidence for σ.
    xy = np.zeros((M, P, 2), np.float32)
    mask = np.zeros((M, P), bool)
    xy[0, 0], xy[1, 0] = (300.0, 200.0), (350.0, 260.0)
    mask[0, 0] = mask[1, 0] = True
    res = associate(RIG, xy, mask, sigma="auto")
    assert int(res.status) & Status.SIGMA_FALLBACK
    assert float(res.sigma_px) == 1.0 and np.isfinite(float(res.tau_px))
    given = associate(RIG, xy, mask, sigma=1.0)
    assert int(given.status) & Status.SIGMA_FALLBACK == 0


def test_thresholds_override_does_not_recompile():
    xy, mask, _, _ = random_scene(RIG, 6, P, sigma=1.0, seed=11)
    associate(RIG, xy, mask, sigma=1.0)
    programs = lambda: cdog_jax._associate._associate_jit._cache_size() + loaded_programs()  # noqa: E731
    before = programs()
    associate(RIG, xy, mask, sigma=3.0, method=Config.paper(delta=0.6, iqr_alpha=1.5))
    assert programs() == before


@pytest.mark.parametrize(
    "xy_shape, mask_shape, match",
    [
        ((4, P, 2), (4, P), "M=5 from the rig"),
        ((M, P, 3), (M, P), r"xy must have shape \(M, P, 2\)"),
        ((M, P, 2), (M, P + 1), "mask must have shape"),
        ((M, 0, 2), (M, 0), "at least one slot"),
    ],
)
def test_bad_shapes_are_refused(xy_shape, mask_shape, match):
    with pytest.raises(ValueError, match=match):
        associate(RIG, np.zeros(xy_shape, np.float32), np.ones(mask_shape, bool))


def test_bad_values_are_refused():
    xy, mask, _, _ = random_scene(RIG, 4, P, seed=12)
    m, i = np.argwhere(mask)[0]
    xy[m, i] = [np.nan, 1.0]
    with pytest.raises(ValueError, match=f"view {m}, slot {i}"):
        associate(RIG, xy, mask)
    with pytest.raises(ValueError, match="mask must be boolean"):
        associate(RIG, np.zeros((M, P, 2), np.float32), np.ones((M, P), np.int32))
    K = np.array(RIG.K)
    K[2] = 0.0
    with pytest.raises(ValueError, match="K of view 2 is singular"):
        associate(
            cdog_jax.Rig(jnp.asarray(K), RIG.R, RIG.t),
            np.zeros((M, P, 2), np.float32),
            np.zeros((M, P), bool),
        )
    R = np.array(RIG.R)
    R[1] *= 1.1
    with pytest.raises(ValueError, match="R of view 1 is not a rotation"):
        associate(
            cdog_jax.Rig(RIG.K, jnp.asarray(R), RIG.t),
            np.zeros((M, P, 2), np.float32),
            np.zeros((M, P), bool),
        )
    with pytest.raises(ValueError, match="sigma must be a number"):
        associate(RIG, np.zeros((M, P, 2), np.float32), np.zeros((M, P), bool), sigma="guess")


def test_bad_batched_rig_names_the_scene():
    K = np.stack([np.array(RIG.K)] * 2)
    K[1, 2] = 0.0
    rigs = cdog_jax.Rig(jnp.asarray(K), jnp.stack([RIG.R] * 2), jnp.stack([RIG.t] * 2))
    with pytest.raises(ValueError, match="rig of scene 1: K of view 2 is singular"):
        associate_batch(rigs, np.zeros((2, M, P, 2), np.float32), np.zeros((2, M, P), bool))
