"""The realistic generator's options do what they say (docs/BENCHMARK.md §7)."""

import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from cdog_jax import Rig, project
from cdog_jax.synthetic import Realism, default_rig, generate_realistic_scene, perturb_rig
from cdog_jax.synthetic._realism import student_t_mad, unit_noise, view_sigmas
from cdog_jax.synthetic._render import _realistic_scene

RIG = default_rig()
GAUSS_MAD = 0.6744897501960817
# One scene shape for every scene test (each new shape costs a compile).
SHAPE = dict(capacity=20, double_capacity=16, clutter_capacity=8)


@jax.jit
def _noise(key, realism):
    return unit_noise(key, (20000,), realism, jnp.float32)


def _opts(**kw):
    return Realism(**kw).as_arrays(jnp.float32)


def test_student_t_mad_known_values():
    mad = jax.jit(jax.vmap(student_t_mad))(jnp.asarray([1.0, 2.0, 3.0, 1e5], jnp.float32))
    # ν = 1: Cauchy, MAD 1; ν = 2: √(2/3); ν = 3: 0.7649 (tables); large ν: the Gaussian's.
    np.testing.assert_allclose(
        np.asarray(mad), [1.0, math.sqrt(2.0 / 3.0), 0.76489, GAUSS_MAD], rtol=2e-4
    )


@pytest.mark.parametrize("nu", [3.0, 1000.0])
def test_student_t_noise_keeps_the_gaussian_mad(nu):
    x = np.asarray(_noise(jax.random.PRNGKey(0), _opts(nu=nu)))
    mad = np.median(np.abs(x), axis=0)
    np.testing.assert_allclose(mad, GAUSS_MAD, rtol=0.04)
    if nu > 100:  # ≈ Gaussian: unit std, Gaussian tail
        np.testing.assert_allclose(x.std(axis=0), 1.0, rtol=0.04)
        assert np.mean(np.abs(x) > 3.0) < 0.005
    else:  # the t_3 quantile (3.182 at 97.5 %) times the MAD scale, and a tail far above the Gaussian's
        q = np.quantile(np.abs(x), 0.95)
        assert q == pytest.approx(3.182 * GAUSS_MAD / 0.76489, rel=0.06)
        assert np.mean(np.abs(x) > 4.0) > 10 * 6.3e-5


def test_far_off_share():
    x = np.asarray(_noise(jax.random.PRNGKey(1), _opts(far_share=0.2, far_scale=20.0)))
    r = np.linalg.norm(x, axis=-1)
    # A far detection's radius exceeds 8 with probability exp(-64 / 800); a near one almost never.
    assert np.mean(r > 8.0) == pytest.approx(0.2 * math.exp(-64.0 / 800.0), abs=0.015)


def test_view_sigmas():
    f = jax.jit(lambda key, realism: view_sigmas(key, jnp.float32(2.0), realism, 4000))
    np.testing.assert_array_equal(np.asarray(f(jax.random.PRNGKey(0), _opts())), 2.0)
    s = np.asarray(f(jax.random.PRNGKey(0), _opts(view_spread=0.5)))
    assert (s > 0).all()
    assert np.std(np.log(s / 2.0)) == pytest.approx(0.5, rel=0.05)


def test_perturb_rig_rms_errors():
    M = 2000
    big = Rig(*(jnp.tile(a, (M // 10,) + (1,) * (a.ndim - 1)) for a in (RIG.K, RIG.R, RIG.t)))
    f = jax.jit(perturb_rig)
    same = f(jax.random.PRNGKey(0), big, _opts())
    np.testing.assert_allclose(np.asarray(same.R), np.asarray(big.R), atol=1e-6)
    np.testing.assert_allclose(np.asarray(same.t), np.asarray(big.t), atol=1e-5)
    moved = f(jax.random.PRNGKey(0), big, _opts(rotation_deg=0.5, translation=0.02))
    dR = np.einsum("mij,mkj->mik", np.asarray(moved.R), np.asarray(big.R))
    angle = np.degrees(np.arccos(np.clip((np.trace(dR, axis1=1, axis2=2) - 1.0) / 2.0, -1.0, 1.0)))
    assert np.sqrt(np.mean(angle**2)) == pytest.approx(0.5, rel=0.08)
    shift = np.linalg.norm(np.asarray(moved.centers) - np.asarray(big.centers), axis=-1)
    assert np.sqrt(np.mean(shift**2)) == pytest.approx(0.02, rel=0.08)
    np.testing.assert_array_equal(np.asarray(moved.K), np.asarray(big.K))


def _scene(seed, sigma=1.0, **realism):
    return generate_realistic_scene(
        jax.random.PRNGKey(seed), RIG, 20, sigma, realism=Realism(**realism), **SHAPE
    )


def test_pose_errors_move_detections_not_points():
    exact = _scene(3, sigma=0.0)
    moved = _scene(3, sigma=0.0, rotation_deg=0.3, translation=0.01)
    np.testing.assert_array_equal(np.asarray(exact.points3d), np.asarray(moved.points3d))
    assert not np.allclose(np.asarray(moved.rig.R), np.asarray(RIG.R))
    # Noise-free detections are the true rig's projections; the nominal rig's are off.
    for s, nominal_off in ((exact, False), (moved, True)):
        mask, inst = np.asarray(s.mask), np.asarray(s.instance)
        xy_true, _ = project(s.rig, s.points3d)  # (M, I, 2)
        xy_nominal, _ = project(RIG, s.points3d)
        m, p = np.nonzero(mask)
        np.testing.assert_allclose(
            np.asarray(s.xy)[m, p], np.asarray(xy_true)[m, inst[m, p]], atol=1e-2
        )
        off = np.linalg.norm(
            np.asarray(s.xy)[m, p] - np.asarray(xy_nominal)[m, inst[m, p]], axis=-1
        )
        assert (np.median(off) > 1.0) == nominal_off


def test_sweep_compiles_once():
    _scene(0, nu=5.0)
    size = _realistic_scene._cache_size()
    for kw in (
        dict(nu=2.0, view_spread=0.3),
        dict(far_share=0.1, double_rate=0.2),
        dict(rotation_deg=0.1, clutter_rate=1.0),
    ):
        _scene(1, sigma=2.0, **kw)
    assert _realistic_scene._cache_size() == size


def test_jit_equals_eager():
    """The numerically delicate kernels (the t radius through expm1 and the MAD search, the
    rotation exponential); the rest of the renderer is indexing. Eager runs op by op, and
    every op compiles on first use, so the whole renderer would take most of the test budget."""
    key, realism = (
        jax.random.PRNGKey(4),
        _opts(nu=3.0, far_share=0.3, rotation_deg=0.5, translation=0.1),
    )
    kernels = (
        lambda key, realism: unit_noise(key, (7,), realism, jnp.float32),
        lambda key, realism: perturb_rig(key, RIG, realism),
    )
    for kernel in kernels:
        jitted, eager = jax.jit(kernel)(key, realism), kernel(key, realism)
        for a, b in zip(jax.tree.leaves(jitted), jax.tree.leaves(eager)):
            np.testing.assert_allclose(np.asarray(a), np.asarray(b), rtol=1e-5, atol=1e-5)


@pytest.mark.parametrize(
    "name, value",
    [
        ("nu", 0.0),
        ("far_share", 1.5),
        ("view_spread", -0.1),
        ("double_rate", -1.0),
        ("rotation_deg", -1.0),
        ("clutter_rate", -2.0),
    ],
)
def test_bad_options_raise(name, value):
    with pytest.raises(ValueError, match=f"Realism.{name}"):
        Realism(**{name: value})


def test_bad_capacity_raises():
    with pytest.raises(ValueError, match="double_capacity"):
        generate_realistic_scene(jax.random.PRNGKey(0), RIG, 3, 1.0, capacity=4, double_capacity=-1)
