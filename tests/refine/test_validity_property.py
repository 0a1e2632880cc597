"""Property: whatever the rig and the detections, every valid group passes the validity gate
(≥ 2 views, in front of its cameras, parallax ≥ Config.min_parallax_deg, member errors ≤
Config.max_err_frac · τ), and garbage in masked slots changes nothing.

Random rigs of 2–12 active cameras (one shape: 12 views, inactive ones masked out, so one
compiled program serves every example), near-degenerate baselines, points in front of and
behind the cameras (a point behind a camera still "projects" through a negative depth:
ghost detections), noise, and NaN / ±inf / 1e30 in the masked slots."""

import jax.numpy as jnp
import numpy as np
import pytest
from helpers import look_at
from hypothesis import HealthCheck, given, settings, strategies as st

import cdog_jax
from cdog_jax import Config, Rig

M, P = 12, 6
W, H = 640, 480
CONFIGS = {"paper": Config.paper(), "extended": Config.extended()}


def _rig(rng, active, near_pair):
    K, R, t = [], [], []
    centers = []
    for m in range(M):
        az, el = rng.uniform(0, 2 * np.pi), rng.uniform(0.1, 1.2)
        c = rng.uniform(2.5, 4.0) * np.array(
            [np.cos(az) * np.cos(el), np.sin(az) * np.cos(el), np.sin(el)]
        )
        if near_pair and m == 1:  # 1e-4 … 1e-2 units from camera 0
            c = centers[0] + rng.uniform(1e-4, 1e-2) * rng.standard_normal(3)
        centers.append(c)
        Rm, tm = look_at(c, rng.uniform(-0.3, 0.3, 3))
        f = rng.uniform(400, 1200)
        Km = np.array([[f, 0.0, W / 2], [0.0, f, H / 2], [0.0, 0.0, 1.0]])
        K.append(-Km if rng.random() < 0.2 else Km)  # K[2,2] = -1 sometimes
        R.append(Rm)
        t.append(tm)
    return np.array(K), np.array(R), np.array(t)


def _scene(seed, n_active, near_pair, behind, sigma):
    rng = np.random.default_rng(seed)
    K, R, t = _rig(rng, n_active, near_pair)
    half = 4.0 if behind else 0.5  # a wide box puts points behind some cameras
    X = rng.uniform(-half, half, (P, 3))
    X_cam = np.einsum("mij,nj->mni", R, X) + t[:, None, :]
    h = np.einsum("mij,mnj->mni", K, X_cam)
    with np.errstate(divide="ignore", invalid="ignore"):
        xy = h[..., :2] / h[..., 2:3]  # through negative depths too: ghost detections
    xy = xy + sigma * rng.standard_normal(xy.shape)
    inside = (
        np.isfinite(xy).all(-1)
        & (xy[..., 0] >= 0)
        & (xy[..., 0] < W)
        & (xy[..., 1] >= 0)
        & (xy[..., 1] < H)
    )
    inside[n_active:] = False
    perm = np.stack([rng.permutation(P) for _ in range(M)])
    xy = np.take_along_axis(np.where(inside[..., None], xy, 0.0), perm[..., None], axis=1)
    mask = np.take_along_axis(inside, perm, axis=1)
    return (K, R, t), xy, mask


def _check_valid_groups(rig, xy, res, cfg):
    K, R, t = (np.asarray(a, np.float64) for a in (rig.K, rig.R, rig.t))
    valid = np.asarray(res.valid)
    groups = np.asarray(res.groups)[valid]
    X = np.asarray(res.points3d, np.float64)[valid]
    bound = cfg.max_err_frac * float(res.tau_px)
    C = -np.einsum("mji,mj->mi", R, t)
    for g, Xg in zip(groups, X):
        views = np.flatnonzero(g >= 0)
        assert len(views) >= 2
        depth = np.einsum("mi,mi->m", R[views, 2], Xg[None, :]) + t[views, 2]
        assert (depth > -1e-5).all(), depth  # f32 sign of a depth ~0 may differ from f64
        rays = Xg[None, :] - C[views]
        u = rays / np.linalg.norm(rays, axis=1, keepdims=True)
        parallax = np.degrees(np.arccos(np.clip(np.abs(u @ u.T), 0.0, 1.0)).max())
        assert parallax >= cfg.min_parallax_deg - 1e-2, parallax
        h = np.einsum("mij,mj->mi", K[views], np.einsum("mij,j->mi", R[views], Xg) + t[views])
        err = np.linalg.norm(h[:, :2] / h[:, 2:3] - xy[views, g[views]], axis=1)
        assert err.max() <= bound * (1 + 1e-3) + 1e-3, (err, bound)


@pytest.mark.parametrize("preset", sorted(CONFIGS))
@settings(
    max_examples=20, deadline=None, derandomize=True, suppress_health_check=[HealthCheck.too_slow]
)
@given(
    seed=st.integers(0, 2**31 - 1),
    n_active=st.integers(2, M),
    near_pair=st.booleans(),
    behind=st.booleans(),
    sigma=st.sampled_from([0.0, 0.5, 2.0]),
    garbage=st.sampled_from([np.nan, np.inf, -np.inf, 1e30]),
)
def test_valid_groups_pass_the_gate_and_masked_slots_change_nothing(
    preset, seed, n_active, near_pair, behind, sigma, garbage
):
    cfg = CONFIGS[preset]
    (K, R, t), xy, mask = _scene(seed, n_active, near_pair, behind, sigma)
    rig = Rig(*(jnp.asarray(a, jnp.float32) for a in (K, R, t)))
    res = cdog_jax.associate(
        rig, jnp.asarray(xy, jnp.float32), jnp.asarray(mask), method=cfg, sigma=max(sigma, 0.5)
    )
    _check_valid_groups(rig, np.asarray(jnp.asarray(xy, jnp.float32), np.float64), res, cfg)
    dirty = np.where(mask[..., None], xy, garbage)
    res2 = cdog_jax.associate(
        rig, jnp.asarray(dirty, jnp.float32), jnp.asarray(mask), method=cfg, sigma=max(sigma, 0.5)
    )
    for field in ("labels", "groups", "valid", "points3d", "err_px"):
        np.testing.assert_array_equal(
            np.asarray(getattr(res2, field)), np.asarray(getattr(res, field)), err_msg=field
        )


@settings(
    max_examples=12, deadline=None, derandomize=True, suppress_health_check=[HealthCheck.too_slow]
)
@given(
    seed=st.integers(0, 2**31 - 1),
    n_active=st.integers(2, M),
    exponent=st.integers(2, 7),
    direction=st.sampled_from([(1.0, 0.0, 0.0), (0.6, -0.8, 0.0), (0.3, 0.4, -0.866)]),
)
def test_a_world_moved_far_away_is_refused_or_centred(seed, n_active, exponent, direction):
    """The same random rigs with their world moved 10²–10⁷ units away (UTM-like): refused
    without an origin exactly where float32 would round the cameras by more than the limit
    (always from 10⁵ here), and given the origin, the groups of the rig near its origin,
    every valid one passing the gate."""
    from cdog_jax.geometry._camera import ROUNDING_PX_LIMIT, rounding_px

    cfg = CONFIGS["paper"]
    (K, R, t), xy, mask = _scene(seed, n_active, False, False, 0.5)
    U, _, Vt = np.linalg.svd(R)
    R = U @ Vt
    offset = 10.0**exponent * np.asarray(direction)
    far = t - np.einsum("mij,j->mi", R, offset)
    too_far = rounding_px(K, R, far, np.float32) > ROUNDING_PX_LIMIT
    assert too_far or exponent < 5
    if too_far:
        with pytest.raises(ValueError, match="units from the world origin"):
            cdog_jax.rig_from_arrays(K, R, far)
    centred = cdog_jax.rig_from_arrays(K, R, far, origin=offset)
    near = cdog_jax.rig_from_arrays(K, R, t)
    xy32, mask = jnp.asarray(xy, jnp.float32), jnp.asarray(mask)
    res = cdog_jax.associate(centred, xy32, mask, method=cfg, sigma=0.5)
    want = cdog_jax.associate(near, xy32, mask, method=cfg, sigma=0.5)
    np.testing.assert_array_equal(np.asarray(res.labels), np.asarray(want.labels))
    _check_valid_groups(centred, np.asarray(xy32, np.float64), res, cfg)
