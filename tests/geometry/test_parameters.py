"""Camera parameterisation: so(3) exponential and logarithm, rig ↔ CameraParams."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from helpers import x64

from cdog_jax.geometry import project
from cdog_jax.geometry._parameters import (
    CameraParams,
    params_from_rig,
    rig_from_params,
    so3_exp,
    so3_log,
)
from cdog_jax.synthetic import default_rig
from cdog_jax.synthetic._rig import negate_intrinsics

DTYPES = ["float32", "float64"]
ATOL = {"float32": 1e-6, "float64": 1e-14}


def rodrigues_np(w):
    """Reference ``exp([w]×)`` in float64 (``(3,)`` → ``(3, 3)``)."""
    w = np.asarray(w, np.float64)
    theta = np.linalg.norm(w)
    if theta == 0:
        return np.eye(3)
    a = w / theta
    A = np.array([[0, -a[2], a[1]], [a[2], 0, -a[0]], [-a[1], a[0], 0]])
    return np.eye(3) + np.sin(theta) * A + (1 - np.cos(theta)) * A @ A


def random_rotvecs(n, seed=0):
    """Random axes with angles spread over [0, π), including tiny ones."""
    rng = np.random.default_rng(seed)
    axis = rng.standard_normal((n, 3))
    axis /= np.linalg.norm(axis, axis=1, keepdims=True)
    angle = np.concatenate(
        [[0.0, 1e-9, 1e-6, 1e-3, 0.05, 0.2, 0.3], rng.uniform(0, np.pi - 1e-3, n - 7)]
    )
    return axis * angle[:, None]


@pytest.mark.parametrize("dtype", DTYPES)
def test_exp_matches_rodrigues_and_is_orthonormal(dtype):
    w = random_rotvecs(64)
    with x64(dtype == "float64"):
        R = np.asarray(jax.jit(so3_exp)(jnp.asarray(w, dtype)), np.float64)
    ref = np.stack([rodrigues_np(v) for v in w])
    assert np.abs(R - ref).max() < 4 * ATOL[dtype]
    assert np.abs(np.einsum("nji,njk->nik", R, R) - np.eye(3)).max() < 4 * ATOL[dtype]
    assert np.allclose(np.linalg.det(R), 1.0, atol=4 * ATOL[dtype])


@pytest.mark.parametrize("dtype", DTYPES)
def test_log_inverts_exp(dtype):
    w = random_rotvecs(64, seed=1)
    w = np.concatenate([w, [[0.0, 0.0, np.pi], [np.pi, 0, 0], [0.0, np.pi - 1e-7, 0.0]]])
    with x64(dtype == "float64"):
        R = jax.jit(so3_exp)(jnp.asarray(w, dtype))
        w_back = so3_log(R)
        R_back = jax.jit(so3_exp)(w_back)
    assert np.all(np.isfinite(np.asarray(w_back)))
    assert np.array_equal(np.asarray(w_back[0]), np.zeros(3))  # the identity, exactly
    assert (
        np.abs(np.asarray(R_back, np.float64) - np.asarray(R, np.float64)).max() < 8 * ATOL[dtype]
    )
    # Away from θ = π the vector itself comes back.
    inner = np.linalg.norm(w, axis=1) < np.pi - 1e-2
    assert np.abs(np.asarray(w_back, np.float64)[inner] - w[inner]).max() < 8 * ATOL[dtype]


@pytest.mark.parametrize("dtype", DTYPES)
def test_exp_gradient_at_zero_is_the_skew_generator(dtype):
    with x64(dtype == "float64"):
        zero = jnp.zeros(3, dtype)
        jacobians = jax.jit(lambda w: (jax.jacfwd(so3_exp)(w), jax.jacrev(so3_exp)(w)))(zero)
    for J in jacobians:  # (3, 3, 3): [:, :, k] = ∂R/∂w_k
        for k in range(3):
            assert np.array_equal(np.asarray(J)[:, :, k], rodrigues_generator(np.eye(3)[k]))


def rodrigues_generator(e):
    return np.array([[0, -e[2], e[1]], [e[2], 0, -e[0]], [-e[1], e[0], 0]])


@pytest.mark.parametrize("dtype", DTYPES)
def test_rig_round_trip(dtype):
    with x64(dtype == "float64"):
        rig = default_rig(dtype=dtype)
        params = params_from_rig(rig)
        back = jax.jit(rig_from_params)(params)
        again = params_from_rig(back)
    tol = ATOL[dtype] * (1 if dtype == "float32" else 100)
    for a, b in ((rig.R, back.R), (rig.t, back.t)):
        assert np.abs(np.asarray(a) - np.asarray(b)).max() < tol
    assert np.abs(np.asarray(rig.K) - np.asarray(back.K)).max() / 1302.0 < tol
    for a, b in zip(jax.tree_util.tree_leaves(params), jax.tree_util.tree_leaves(again)):
        assert np.abs(np.asarray(a) - np.asarray(b)).max() < tol * 1302.0


def test_negated_intrinsics_map_to_an_equivalent_rig():
    rig = default_rig()
    negated = negate_intrinsics(rig, [0, 3, 7])
    params = params_from_rig(negated)
    back = jax.jit(rig_from_params)(params)
    assert np.all(np.asarray(back.K[:, 2, 2]) == 1.0)
    assert np.abs(np.asarray(back.K) - np.asarray(rig.K)).max() == 0.0
    X = jnp.asarray(np.random.default_rng(0).uniform(-0.5, 0.5, (50, 3)), jnp.float32)
    xy_neg, ok_neg = jax.jit(project)(negated, X)
    xy_back, ok_back = jax.jit(project)(back, X)
    assert np.array_equal(np.asarray(ok_neg), np.asarray(ok_back))
    assert np.abs(np.asarray(xy_neg) - np.asarray(xy_back)).max() < 1e-3  # px


def test_skew_and_nonunit_K22_are_kept():
    rig = default_rig(num_views=3)
    K = rig.K.at[:, 0, 1].set(jnp.asarray([0.5, -2.0, 0.0])) * 2.5  # K[2,2] = 2.5
    params = params_from_rig(type(rig)(K, rig.R, rig.t))
    assert np.allclose(np.asarray(params.skew), [0.5, -2.0, 0.0], atol=1e-5)
    assert np.allclose(
        np.asarray(jax.jit(rig_from_params)(params).K), np.asarray(K) / 2.5, rtol=1e-6
    )


def test_finite_differences_of_rig_from_params():
    """Central differences (float64) of a scalar function of ``rig_from_params`` for every
    parameter type, with view 0 at exactly ``rotvec = 0``."""
    with x64(True):
        params = params_from_rig(default_rig(num_views=3, dtype=jnp.float64))
        params = CameraParams(
            rotvec=params.rotvec.at[0].set(0.0),
            t=params.t,
            focal=params.focal,
            principal=params.principal,
            skew=params.skew,
        )
        rng = np.random.default_rng(0)
        weights = [jnp.asarray(rng.standard_normal(s)) for s in [(3, 3, 3), (3, 3, 3), (3, 3)]]

        def f(p):
            rig = rig_from_params(p)
            # Nonlinear in every entry, with K scaled so all three terms matter.
            return (
                jnp.sum(weights[0] * jnp.sin(rig.K / 1000.0))
                + jnp.sum(weights[1] * rig.R**3)
                + jnp.sum(weights[2] * jnp.sin(rig.t))
            )

        value_and_grad = jax.jit(jax.value_and_grad(f))
        grad = value_and_grad(params)[1]
        scales = {"rotvec": 1.0, "t": 1.0, "focal": 1000.0, "principal": 300.0, "skew": 100.0}
        for name, scale in scales.items():
            value = getattr(params, name)
            g = np.asarray(getattr(grad, name)).reshape(-1)
            assert np.all(np.isfinite(g))
            h = 1e-5 * scale
            fd = np.zeros(g.size)
            for k in range(g.size):  # reuses the compiled function
                e = jnp.zeros(g.size, jnp.float64).at[k].set(h).reshape(value.shape)
                plus = value_and_grad(eqx_replace(params, name, value + e))[0]
                minus = value_and_grad(eqx_replace(params, name, value - e))[0]
                fd[k] = (float(plus) - float(minus)) / (2 * h)
            assert np.abs(g - fd).max() <= 1e-7 * max(np.abs(fd).max(), 1e-3 / scale), name


def eqx_replace(params, name, value):
    fields = {k: getattr(params, k) for k in ("rotvec", "t", "focal", "principal", "skew")}
    fields[name] = value
    return CameraParams(**fields)
