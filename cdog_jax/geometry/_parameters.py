"""Camera parameters for optimisation: rotation vectors (so(3)), translations, intrinsics.

A rotation is a 3-vector ``w = θ a`` (angle θ in radians about the unit axis ``a``),
mapped to ``R = exp([w]×)`` by Rodrigues' formula. Near ``θ = 0`` the coefficients are
evaluated by Taylor series with the double-``where`` pattern, so values and gradients are
finite and correct at exactly zero, in float32 and float64.
"""

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .._expect import ARRAY, expect_args
from .._types import Array, Float
from ._camera import Rig


def _taylor_threshold(dtype) -> float:
    """The ``θ²`` below which the Taylor branch of :func:`_sinc_sq` is used.

    Balances the Taylor truncation of the derivative (``~θ⁵/840``) against the cancellation
    in the autodiff derivative of ``sin θ / θ`` (``~eps/θ``): ``θ⁶ = 840 eps``, i.e.
    ``θ ≈ 0.2`` in float32 and ``θ ≈ 0.008`` in float64, both with value errors below eps.
    """
    return float(np.cbrt(840.0 * float(jnp.finfo(dtype).eps)))


def _sinc_sq(s: Float[Array, "*S"]) -> Float[Array, "*S"]:
    """``sin(√s) / √s`` for ``s = θ² ≥ 0``, with finite value and derivative at ``s = 0``."""
    small = s < _taylor_threshold(s.dtype)
    # Both branches are evaluated and their gradients multiplied by 0 where unused: the
    # direct branch must not see s = 0 (sqrt and 1/θ have infinite derivatives there).
    theta = jnp.sqrt(jnp.where(small, 1.0, s))
    direct = jnp.sin(theta) / theta
    taylor = 1.0 - s / 6.0 + s * s / 120.0
    return jnp.where(small, taylor, direct)


def _hat(w: Float[Array, "*S 3"]) -> Float[Array, "*S 3 3"]:
    """The skew matrix ``[w]×`` with ``[w]× v = w × v``."""
    x, y, z = w[..., 0], w[..., 1], w[..., 2]
    zero = jnp.zeros_like(x)
    return jnp.stack(
        [jnp.stack([zero, -z, y], -1), jnp.stack([z, zero, -x], -1), jnp.stack([-y, x, zero], -1)],
        -2,
    )


def so3_exp(rotvec: Float[Array, "*S 3"]) -> Float[Array, "*S 3 3"]:
    """Rotation matrices ``(*S, 3, 3)`` of rotation vectors ``(*S, 3)`` (radians).

    ``R = I + A [w]× + B [w]×²`` with ``A = sin θ / θ`` and ``B = (1 − cos θ) / θ²``,
    the latter written ``½ (sin(θ/2) / (θ/2))²`` to avoid cancellation. Values and
    gradients are finite everywhere; at ``w = 0``, ``∂R/∂w_k = [e_k]×``.
    """
    expect_args("so3_exp", rotvec=(rotvec, ARRAY))
    s = jnp.sum(rotvec * rotvec, axis=-1)  # θ², (*S,)
    A = _sinc_sq(s)
    half = _sinc_sq(0.25 * s)
    B = 0.5 * half * half
    W = _hat(rotvec)
    eye = jnp.broadcast_to(jnp.eye(3, dtype=rotvec.dtype), W.shape)
    return (
        eye + A[..., None, None] * W + B[..., None, None] * jnp.einsum("...ij,...jk->...ik", W, W)
    )


def _so3_log_one(R: Float[Array, "3 3"]) -> Float[Array, "3"]:
    v = 0.5 * jnp.stack([R[2, 1] - R[1, 2], R[0, 2] - R[2, 0], R[1, 0] - R[0, 1]])  # sin θ · a
    c = jnp.clip(0.5 * (R[0, 0] + R[1, 1] + R[2, 2] - 1.0), -1.0, 1.0)  # cos θ
    n2 = jnp.sum(v * v)
    n2_pos = n2 > 0
    n = jnp.where(n2_pos, jnp.sqrt(jnp.where(n2_pos, n2, 1.0)), 0.0)  # sin θ
    theta = jnp.arctan2(n, c)

    # θ ≤ π/2: w = v θ / sin θ, where θ / sin θ = arcsin(n) / n; its Taylor series up to n⁴
    # is exact to eps for n² < cbrt(eps).
    small = n2 < float(np.cbrt(float(jnp.finfo(R.dtype).eps)))
    ratio = jnp.where(small, 1.0 + n2 / 6.0 + 0.075 * n2 * n2, theta / jnp.where(small, 1.0, n))
    w_near = v * ratio

    # θ > π/2: sin θ → 0 near π and v loses the axis; read it from the symmetric part,
    # (R + Rᵀ)/2 − cos θ I = (1 − cos θ) a aᵀ, and take the sign of a from v.
    far = c < 0
    S = (0.5 * (R + R.T) - c * jnp.eye(3, dtype=R.dtype)) / jnp.where(far, 1.0 - c, 1.0)
    i = jnp.argmax(jnp.diagonal(S))
    col = S[:, i]
    d = col[i]
    d_ok = d > 0.1  # ≥ 1/3 for a rotation with θ > π/2
    a = col / jnp.sqrt(jnp.where(d_ok, d, 1.0))
    a = jnp.where(jnp.dot(a, v) < 0, -a, a)
    w_far = theta * a
    return jnp.where(far, w_far, w_near)


def so3_log(R: Float[Array, "*S 3 3"]) -> Float[Array, "*S 3"]:
    """Rotation vectors ``(*S, 3)`` (radians, ``θ ∈ [0, π]``) of rotations ``(*S, 3, 3)``.

    For initialisation. Accurate to a few eps for every angle: ``θ = atan2(sin θ, cos θ)``,
    the axis from the skew part for ``θ ≤ π/2`` and from the symmetric part beyond (where
    the skew part vanishes as ``θ → π``). Within ~eps of ``θ = π`` the sign of the result is
    arbitrary (both represent the same rotation). Values and gradients are finite; the
    gradient is not meant to be used near ``θ = π``. Inputs should be orthonormal.
    """
    expect_args("so3_log", R=(R, ARRAY))
    return _so3_log(R)


# The conversions are jitted here so that eager calls compile once rather than op by op
# (seconds on a small CPU); under an outer jit, vmap or grad they are simply inlined.
_so3_log = jax.jit(jnp.vectorize(_so3_log_one, signature="(3,3)->(3)"))


class CameraParams(eqx.Module):
    """Per-view camera parameters for optimisation (a batch of rigs adds leading axes).

    ``K = [[fx, skew, cx], [0, fy, cy], [0, 0, 1]]``, ``R = so3_exp(rotvec)``, world→camera
    ``X_cam = R X + t``.

    Attributes:
        rotvec: ``(M, 3)`` rotation vectors (radians).
        t: ``(M, 3)`` translations (scene units).
        focal: ``(M, 2)`` focal lengths ``(fx, fy)`` (pixels; the sign is kept as given).
        principal: ``(M, 2)`` principal point ``(cx, cy)`` (pixels).
        skew: ``(M,)`` skew ``K[0, 1]`` (pixels).
    """

    rotvec: Float[Array, "*B M 3"]
    t: Float[Array, "*B M 3"]
    focal: Float[Array, "*B M 2"]
    principal: Float[Array, "*B M 2"]
    skew: Float[Array, "*B M"]


def params_from_rig(rig: Rig) -> CameraParams:
    """The :class:`CameraParams` of a rig (``M`` views: fields ``(M, 3)``, ``(M, 2)``, ``(M,)``).

    ``K`` is divided by ``K[2, 2]`` first: pixels ``x ~ K X_cam`` do not change when K is
    scaled, so a ``K[2, 2] = −1`` export maps to the equivalent ``K[2, 2] = 1`` camera
    (with negated focal lengths and principal point). ``K[1, 0]``, ``K[2, 0]`` and
    ``K[2, 1]`` are assumed 0 (upper-triangular K). ``R`` goes through :func:`so3_log`.
    """
    expect_args("params_from_rig", rig=(rig, Rig))
    return _params_from_rig(rig)


@jax.jit
def _params_from_rig(rig: Rig) -> CameraParams:
    K = rig.K / rig.K[..., 2:3, 2:3]
    focal = jnp.stack([K[..., 0, 0], K[..., 1, 1]], axis=-1)
    principal = jnp.stack([K[..., 0, 2], K[..., 1, 2]], axis=-1)
    return CameraParams(
        rotvec=so3_log(rig.R), t=rig.t, focal=focal, principal=principal, skew=K[..., 0, 1]
    )


def rig_from_params(params: CameraParams) -> Rig:
    """The :class:`Rig` (``K, R (M, 3, 3)``, ``t (M, 3)``, ``K[2, 2] = 1``) of camera parameters.

    Differentiable everywhere, ``rotvec = 0`` included.
    """
    expect_args("rig_from_params", params=(params, CameraParams))
    return _rig_from_params(params)


@jax.jit
def _rig_from_params(params: CameraParams) -> Rig:
    fx, fy = params.focal[..., 0], params.focal[..., 1]
    cx, cy = params.principal[..., 0], params.principal[..., 1]
    zero = jnp.zeros_like(fx)
    one = jnp.ones_like(fx)
    K = jnp.stack(
        [
            jnp.stack([fx, params.skew, cx], -1),
            jnp.stack([zero, fy, cy], -1),
            jnp.stack([zero, zero, one], -1),
        ],
        -2,
    )
    return Rig(K, so3_exp(params.rotvec), params.t)
