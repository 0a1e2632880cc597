"""Differentiable BPE of an association (docs/ALGORITHM.md §8): values against NumPy, gradients against
finite differences, degenerate rows, robust kernels, jit and vmap, given points."""

import functools

import jax
import jax.numpy as jnp
import numpy as np
from helpers import project_np, run_with_xla_defaults, x64

from cdog_jax import Rig
from cdog_jax.calibration._bpe_loss import bpe, group_bpe
from cdog_jax.geometry import triangulate
from cdog_jax.geometry._parameters import CameraParams, params_from_rig, rig_from_params
from cdog_jax.synthetic import default_rig, generate_scene

FIELDS = ("rotvec", "t", "focal", "principal", "skew")


def gt_groups(instance, G=12):
    """Ground-truth ``(G, M)`` slot table and validity from ``instance (M, P)``."""
    instance = np.asarray(instance)
    M = instance.shape[0]
    groups = np.full((G, M), -1, np.int32)
    for m in range(M):
        for i in np.flatnonzero(instance[m] >= 0):
            groups[instance[m, i], m] = i
    return groups, (groups >= 0).sum(axis=1) >= 2


@functools.cache
def _scene32(sigma, seed):
    rig = default_rig()
    return rig, generate_scene(jax.random.PRNGKey(seed), rig, 12, sigma, capacity=12)


def scene(dtype="float32", sigma=1.0, seed=0):
    """``(rig, xy, groups, valid)`` of a 12-point scene on the built-in rig. The float64
    variant reuses the float32 draw (pixels cast; at σ = 0 re-projected in float64, so
    they are exact)."""
    rig, sc = _scene32(sigma, seed)
    groups, valid = gt_groups(sc.instance)
    if dtype == "float32":
        return rig, sc.xy, jnp.asarray(groups), jnp.asarray(valid)
    with x64(True):
        rig = default_rig(dtype=jnp.float64)
        xy = np.asarray(sc.xy, np.float64)
        if sigma == 0:
            exact, _ = project_np(rig, np.asarray(sc.points3d, np.float64))  # (M, P, 2)
            inst = np.asarray(sc.instance)
            m, i = np.nonzero(inst >= 0)
            xy[m, i] = exact[m, inst[m, i]]
        return rig, jnp.asarray(xy), jnp.asarray(groups), jnp.asarray(valid)


def residuals_np(rig, xy, groups, valid):
    """Squared member residuals (px²) per valid group, docs/ALGORITHM.md §8 in NumPy float64: the
    group's multi-view DLT (rows ``x̂ P3 − P1``, ``ŷ P3 − P2`` in normalised coordinates,
    least squares by SVD), projected with the general K."""
    K, R, t = (np.asarray(a, np.float64) for a in (rig.K, rig.R, rig.t))
    xy = np.asarray(xy, np.float64)
    out = []
    for g in np.flatnonzero(np.asarray(valid)):
        views = np.flatnonzero(np.asarray(groups[g]) >= 0)
        obs = xy[views, np.asarray(groups[g])[views]]  # (k, 2)
        rows = []
        for m, x in zip(views, obs):
            ray = np.linalg.solve(K[m], [x[0], x[1], 1.0])
            Rt = np.concatenate([R[m], t[m][:, None]], axis=1)
            rows += [ray[0] / ray[2] * Rt[2] - Rt[0], ray[1] / ray[2] * Rt[2] - Rt[1]]
        A = np.array(rows)
        X = np.linalg.lstsq(A[:, :3], -A[:, 3], rcond=None)[0]
        h = np.einsum("mij,mj->mi", K[views], np.einsum("mij,j->mi", R[views], X) + t[views])
        out.append(np.sum((h[:, :2] / h[:, 2:] - obs) ** 2, axis=1))
    return out


def camera0_frame(rig):
    """The same cameras with the world frame moved to camera 0 (so ``R_0 = I``, ``t_0 = 0``
    and its rotation vector is exactly 0); pixels are unchanged."""
    R0, t0 = rig.R[0], rig.t[0]
    R = jnp.einsum("mij,kj->mik", rig.R, R0)
    t = rig.t - jnp.einsum("mij,j->mi", R, t0)
    params = params_from_rig(Rig(rig.K, R, t))
    return CameraParams(
        rotvec=params.rotvec.at[0].set(0.0),
        t=params.t.at[0].set(0.0),
        focal=params.focal,
        principal=params.principal,
        skew=params.skew,
    )


def perturbed(params, seed):
    """A drifted calibration: ~0.3° rotations, ~1 % translations and focal lengths, a few px of
    principal point and skew; view 0 keeps its exact zero rotation."""
    rng = np.random.default_rng(seed)

    def noise(a, scale):
        return a + jnp.asarray(scale * rng.standard_normal(a.shape), a.dtype)

    return CameraParams(
        rotvec=noise(params.rotvec, 5e-3).at[0].set(0.0),
        t=noise(params.t, 0.02),
        focal=noise(params.focal, 13.0),
        principal=noise(params.principal, 3.0),
        skew=noise(params.skew, 1.0),
    )


def replace(params, name, value):
    fields = {k: getattr(params, k) for k in FIELDS}
    fields[name] = value
    return CameraParams(**fields)


def degenerate_table(groups, valid):
    """The ground-truth table with some groups cut to exactly 2 views, plus rows that must
    not count: padded (-1, invalid), invalid with members, valid with 1 and 0 members.
    Returns ``(table, table_valid, clean, clean_valid)``: with and without the extra rows."""
    groups, valid = np.array(groups), np.array(valid)
    for g in np.flatnonzero((groups >= 0).sum(axis=1) >= 3)[:3]:
        groups[g, np.flatnonzero(groups[g] >= 0)[2:]] = -1
    M = groups.shape[1]
    one = np.full(M, -1, np.int32)
    first = np.flatnonzero(groups[0] >= 0)[0]
    one[first] = groups[0, first]
    extra = np.stack([np.full(M, -1, np.int32), groups[1], one, np.full(M, -1, np.int32)])
    table = np.concatenate([groups, extra])
    return table, np.concatenate([valid, [False, False, True, True]]), groups, valid


def padded_slots(groups, shape):
    """``(M, P)`` bool: slots no ground-truth group references (padding)."""
    padded = np.ones(shape, bool)
    for g, m in zip(*np.nonzero(np.asarray(groups) >= 0)):
        padded[m, int(groups[g, m])] = False
    return padded


def test_bpe_matches_numpy():
    """Plain (eager) float32 calls against NumPy float64; the float64 check is in
    :func:`test_gradients_match_finite_differences`."""
    rig, xy, groups, valid = scene("float32")
    per_group = np.asarray(group_bpe(rig, xy, groups, valid), np.float64)
    total = float(bpe(rig, xy, groups, valid))
    ref = np.array([r.mean() for r in residuals_np(rig, xy, groups, valid)])
    assert ref.min() > 0.05  # σ = 1 px: a meaningful comparison
    np.testing.assert_allclose(per_group[np.asarray(valid)], ref, rtol=2e-3)
    assert np.all(per_group[~np.asarray(valid)] == 0)
    np.testing.assert_allclose(total, ref.mean(), rtol=2e-3)


def test_gradients_match_finite_differences():
    """float64 central differences of ``bpe ∘ rig_from_params`` for every parameter, at a
    drifted calibration with view 0 at exactly ``rotvec = 0``, on a table with groups of
    exactly 2 views, padded, invalid, 1-member and empty rows, and NaN in padded slots.
    Steps are scaled to each parameter (1e-6 rad, 1e-6 units, 1e-3 px for focal length and
    principal point, 1e-4 px skew). The value matches NumPy on the clean table to 1e-9."""
    rig, xy, groups, valid = scene("float64")
    table, table_valid, clean, clean_valid = degenerate_table(groups, valid)
    assert int(((clean >= 0).sum(axis=1) == 2).sum()) >= 3
    padded = padded_slots(groups, xy.shape[:2])
    steps = {"rotvec": 1e-6, "t": 1e-6, "focal": 1e-3, "principal": 1e-3, "skew": 1e-4}
    with x64(True):
        xy_garbage = jnp.where(jnp.asarray(padded)[..., None], jnp.nan, xy)
        params = perturbed(camera0_frame(rig), seed=1)
        table_args = (jnp.asarray(table), jnp.asarray(table_valid))

        @jax.jit
        def value_and_grad(p, xy):
            return jax.value_and_grad(
                lambda p, xy: bpe(rig_from_params(p), xy, *table_args), argnums=(0, 1)
            )(p, xy)

        value, (grad, grad_xy) = value_and_grad(params, xy_garbage)
        ref = np.mean(
            [r.mean() for r in residuals_np(rig_from_params(params), xy, clean, clean_valid)]
        )
        np.testing.assert_allclose(float(value), ref, rtol=1e-9)
        assert np.all(np.isfinite(np.asarray(grad_xy)))
        assert np.all(np.asarray(grad_xy)[padded] == 0)  # padding gets no gradient
        errors = {}
        for name in FIELDS:
            g = np.asarray(getattr(grad, name)).reshape(-1)
            assert np.all(np.isfinite(g)), name
            value0 = getattr(params, name)
            fd = np.zeros(g.size)
            for k in range(g.size):  # reuses the compiled function: no vmap compilation
                step = jnp.zeros(g.size, jnp.float64).at[k].set(steps[name]).reshape(value0.shape)
                plus = value_and_grad(replace(params, name, value0 + step), xy_garbage)[0]
                minus = value_and_grad(replace(params, name, value0 - step), xy_garbage)[0]
                fd[k] = (float(plus) - float(minus)) / (2 * steps[name])
            errors[name] = np.abs(g - fd).max() / np.abs(fd).max()
    assert max(errors.values()) < 1e-6, errors
    assert np.abs(np.asarray(grad.rotvec[0])).max() > 0  # the zero rotation is not a dead spot


def test_robust_kernels():
    """Huber and Cauchy against their formulas; equal to l2 for residuals well below the
    scale, smaller for residuals above it; the scale may be traced; gradients finite."""
    rig, xy, groups, valid = scene("float32")
    s = residuals_np(rig, xy, groups, valid)  # px², per valid group
    points = _scene32(1.0, 0)[1].points3d[:12]  # ground truth (G, 3)

    @jax.jit
    def kernels(c):
        values = [
            group_bpe(rig, xy, groups, valid, loss=loss, scale_px=c)
            for loss in ("l2", "huber", "cauchy")
        ]

        def joint(rig, points):  # gradients of both kernels; non-members have s = 0 exactly
            kw = {"scale_px": c, "points3d": points}
            return bpe(rig, xy, groups, valid, loss="huber", **kw) + bpe(
                rig, xy, groups, valid, loss="cauchy", **kw
            )

        return values, jax.grad(joint, argnums=(0, 1))(rig, points)

    keep = np.asarray(valid)
    for c in (100.0, 0.5):
        values, grads = kernels(jnp.asarray(c))
        l2, huber, cauchy = (np.asarray(a)[keep] for a in values)
        ref_huber = [np.where(r <= c * c, r, 2 * c * np.sqrt(r) - c * c).mean() for r in s]
        ref_cauchy = [(c * c * np.log1p(r / (c * c))).mean() for r in s]
        np.testing.assert_allclose(huber, ref_huber, rtol=2e-3)
        np.testing.assert_allclose(cauchy, ref_cauchy, rtol=2e-3)
        if c == 100.0:  # small residuals: both are the squared error
            np.testing.assert_allclose(huber, l2, rtol=1e-6)
            np.testing.assert_allclose(cauchy, l2, rtol=1e-3)
        else:  # large residuals are down-weighted
            assert np.all(huber < l2) and np.all(cauchy < l2)
        for leaf in jax.tree_util.tree_leaves(grads):
            assert np.all(np.isfinite(np.asarray(leaf)))


def test_jit_and_vmap_equal_plain_calls():
    """With XLA's defaults, in a child process. Under the suite's switches (no fused
    multiply-add), float32 plain and jitted calls of these scenes differ by up to 1.03e-5
    relative, against 3.6e-6 with the defaults: the tolerance below is the defaults'."""
    run_with_xla_defaults(__file__, "jit_and_vmap_equal_plain_calls")


def jit_and_vmap_equal_plain_calls():
    rig = scene("float32")[0]
    scenes = [scene("float32", seed=k)[1:] for k in range(3)]
    rigs = [rig_from_params(perturbed(params_from_rig(rig), seed=k)) for k in (2, 3)]
    plain_scenes = np.array([float(bpe(rig, *s)) for s in scenes])
    plain_rigs = np.array([float(bpe(r, *scenes[0])) for r in rigs])

    stacked = [jnp.stack(a) for a in zip(*scenes)]
    rig_batch = jax.tree_util.tree_map(lambda *a: jnp.stack(a), *rigs)

    @jax.jit
    def batched(rig_batch, stacked):
        over_scenes = jax.vmap(bpe, in_axes=(None, 0, 0, 0))(rig, *stacked)
        over_rigs = jax.vmap(bpe, in_axes=(0, None, None, None))(rig_batch, *scenes[0])
        return over_scenes, over_rigs, bpe(rig, *scenes[0])

    over_scenes, over_rigs, jitted = batched(rig_batch, stacked)
    np.testing.assert_allclose(np.asarray(over_scenes), plain_scenes, rtol=1e-5)
    np.testing.assert_allclose(np.asarray(over_rigs), plain_rigs, rtol=1e-5)
    np.testing.assert_allclose(float(jitted), plain_scenes[0], rtol=1e-5)


def test_given_points_equal_triangulated_and_are_stationary():
    """σ = 0, float64: the DLT points given as ``points3d`` reproduce the triangulated BPE,
    and its gradient w.r.t. them vanishes (they reproject exactly)."""
    rig, xy, groups, valid = scene("float64", sigma=0.0)
    with x64(True):

        @jax.jit
        def run(X):
            tracks = xy[jnp.arange(xy.shape[0])[:, None], jnp.maximum(groups, 0).T]  # (M, G, 2)
            X_dlt, ok = triangulate(rig, tracks, ((groups >= 0) & valid[:, None]).T)
            inside = bpe(rig, xy, groups, valid)
            given, g = jax.value_and_grad(lambda X: bpe(rig, xy, groups, valid, points3d=X))(
                X_dlt + X
            )
            return ok, inside, given, g

        ok, inside, given, g = run(jnp.zeros((groups.shape[0], 3)))
        _, _, _, g_off = run(jnp.full((groups.shape[0], 3), 1e-3))
    assert np.array_equal(np.asarray(ok), np.asarray(valid))
    assert float(inside) < 1e-12  # px²: noise-free
    np.testing.assert_allclose(float(given), float(inside), rtol=1e-6, atol=1e-15)
    assert np.abs(np.asarray(g)).max() < 1e-6 * np.abs(np.asarray(g_off)).max()
