"""What real detectors add to the benchmark's Gaussian noise (docs/BENCHMARK.md §7): heavy tails,
per-view noise levels, double detections, clutter and camera pose errors unknown to the method.

:class:`Realism` holds the numbers; every field is a pytree leaf, so a sweep over any of
them under ``jit`` compiles once. The functions here draw the per-view and per-detection
randomness; :mod:`._render` turns 3D points into detections with them.
"""

from __future__ import annotations

import math

import equinox as eqx
import jax
import jax.numpy as jnp
from jaxtyping import PRNGKeyArray

from .._types import Array, Float
from ..geometry._camera import Rig
from ..geometry._parameters import so3_exp

_GAUSS_MAD = 0.6744897501960817  # Φ⁻¹(3/4): the median of |N(0, 1)|
# Above this ν the Student-t is replaced by the Gaussian (its limit): the quantile search
# loses precision in float32 long before ν = ∞.
_NU_GAUSSIAN = 1.0e4


class Realism(eqx.Module):
    """Options of the realistic generator; all numbers, all traced (a sweep compiles once).

    The defaults are the benchmark's model: Gaussian noise of σ in every view, no doubles,
    no clutter, exact cameras.

    Attributes:
        nu: Student-t degrees of freedom of the 2D noise (``> 0``; ``inf``: Gaussian). The
            t noise is scaled so that each coordinate's median absolute deviation equals
            that of ``N(0, σ²)``: σ stays the scale of the bulk while the tail grows.
        far_share: share of detections, in ``[0, 1]``, whose noise is multiplied by
            ``far_scale`` (a Gaussian with a share of far-off detections).
        far_scale: noise multiplier of the far-off detections (``>= 1``).
        view_spread: ``s >= 0``: view ``m`` has noise ``σ_m = σ · exp(s · z_m)``,
            ``z_m ~ N(0, 1)`` (``s = 0.5``: σ_m within ×/÷ 2.7 of σ for 95 % of views).
        double_rate: probability in ``[0, 1]`` that a detection has a second detection of
            the same point in the same view (a detector firing twice).
        double_offset_px: std (pixels, per coordinate) of a double's offset from its detection.
        rotation_deg: RMS angle (degrees) of each camera's rotation error.
        translation: RMS length (scene units) of each camera centre's position error.
        clutter_rate: mean number of false detections per view (Poisson), uniform in the image.
    """

    nu: float | Float[Array, ""] = math.inf
    far_share: float | Float[Array, ""] = 0.0
    far_scale: float | Float[Array, ""] = 20.0
    view_spread: float | Float[Array, ""] = 0.0
    double_rate: float | Float[Array, ""] = 0.0
    double_offset_px: float | Float[Array, ""] = 3.0
    rotation_deg: float | Float[Array, ""] = 0.0
    translation: float | Float[Array, ""] = 0.0
    clutter_rate: float | Float[Array, ""] = 0.0

    def __check_init__(self):
        # Traced fields (inside jit or vmap) cannot be checked; Python numbers are.
        checks = (
            ("nu", lambda v: v > 0),
            ("far_share", lambda v: 0 <= v <= 1),
            ("far_scale", lambda v: v >= 1),
            ("view_spread", lambda v: v >= 0),
            ("double_rate", lambda v: 0 <= v <= 1),
            ("double_offset_px", lambda v: v >= 0),
            ("rotation_deg", lambda v: v >= 0),
            ("translation", lambda v: v >= 0),
            ("clutter_rate", lambda v: v >= 0),
        )
        for name, ok in checks:
            value = getattr(self, name)
            if isinstance(value, (int, float)) and not ok(value):
                raise ValueError(f"Realism.{name} is out of range; got {value!r}")

    def as_arrays(self, dtype) -> Realism:
        """The same options as ``()`` arrays of ``dtype`` (one jit cache entry for any values)."""
        return jax.tree.map(lambda v: jnp.asarray(v, dtype), self)


def student_t_mad(nu: Float[Array, ""]) -> Float[Array, ""]:
    """Median absolute deviation of a standard Student-t with ``nu`` degrees of freedom, ``()``.

    ``q`` solves ``F_ν(q) = 3/4``; with ``x = ν / (ν + q²)`` that is ``I_x(ν/2, 1/2) = 1/2``
    (regularised incomplete beta), solved by 60 bisection steps in ``x``. ``ν >= 1e4``
    gives the Gaussian value ``Φ⁻¹(3/4)``.
    """
    dtype = nu.dtype

    def solve(nu):
        def step(_, bounds):
            lo, hi = bounds
            mid = 0.5 * (lo + hi)
            above = jax.scipy.special.betainc(0.5 * nu, jnp.asarray(0.5, dtype), mid) > 0.5
            return jnp.where(above, lo, mid), jnp.where(above, mid, hi)

        lo, hi = jax.lax.fori_loop(0, 60, step, (jnp.asarray(0.0, dtype), jnp.asarray(1.0, dtype)))
        x = jnp.clip(0.5 * (lo + hi), jnp.finfo(dtype).tiny, 1.0)
        return jnp.sqrt(nu * (1.0 - x) / x)

    # A cond, not a where: outside jit (and in a jitted scalar call) the Gaussian skips the search.
    big = nu >= _NU_GAUSSIAN
    return jax.lax.cond(
        big, lambda nu: jnp.asarray(_GAUSS_MAD, dtype), solve, jnp.where(big, 1.0, nu)
    )


def unit_noise(
    key: PRNGKeyArray, shape: tuple[int, ...], realism: Realism, dtype
) -> Float[Array, "*S 2"]:
    """2D noise of unit scale, ``(*shape, 2)``: bivariate Student-t (isotropic, one radius per
    detection, as a detector's miss is off in both coordinates; each coordinate is a
    Student-t with ``nu`` degrees of freedom) scaled so that each coordinate's MAD is
    ``Φ⁻¹(3/4)`` (that of ``N(0, 1)``), times ``far_scale`` on a ``far_share`` of
    detections. Multiply by σ (pixels).

    Drawn in closed form, without a gamma draw: the squared radius of the standard bivariate
    t is ``ν (W^(-2/ν) - 1)`` with ``W`` uniform in (0, 1] (its half is F(2, ν)-distributed),
    and ``-2 ln W`` (the Gaussian's) in the limit ``ν → ∞``.
    """
    k_radius, k_angle, k_far = jax.random.split(key, 3)
    nu = jnp.asarray(realism.nu, dtype)
    gaussian = nu >= _NU_GAUSSIAN
    nu_safe = jnp.where(gaussian, 1.0, nu)
    W = 1.0 - jax.random.uniform(k_radius, shape, dtype=dtype)  # (0, 1]
    log_w = jnp.log(W)
    r2_t = nu_safe * jnp.expm1(-2.0 * log_w / nu_safe) * (_GAUSS_MAD / student_t_mad(nu)) ** 2
    r2 = jnp.where(gaussian, -2.0 * log_w, r2_t)
    angle = (2.0 * math.pi) * jax.random.uniform(k_angle, shape, dtype=dtype)
    far = jax.random.uniform(k_far, shape, dtype=dtype) < jnp.asarray(realism.far_share, dtype)
    radius = jnp.sqrt(r2) * jnp.where(far, jnp.asarray(realism.far_scale, dtype), 1.0)
    return radius[..., None] * jnp.stack([jnp.cos(angle), jnp.sin(angle)], axis=-1)


def view_sigmas(
    key: PRNGKeyArray, sigma_px: Float[Array, ""], realism: Realism, M: int
) -> Float[Array, " M"]:
    """Noise level of every view ``σ_m = σ · exp(s · z_m)`` (pixels), ``(M,)``."""
    dtype = sigma_px.dtype
    z = jax.random.normal(key, (M,), dtype=dtype)
    return sigma_px * jnp.exp(jnp.asarray(realism.view_spread, dtype) * z)


def perturb_rig(key: PRNGKeyArray, rig: Rig, realism: Realism) -> Rig:
    """The true cameras ``K, R (M, 3, 3)``, ``t (M, 3)`` of a rig calibrated with errors: every view rotated about its centre
    by a rotation vector of RMS angle ``rotation_deg`` and moved by a vector of RMS length
    ``translation`` (isotropic Gaussians), intrinsics unchanged. Detections are rendered
    with this rig; the method gets ``rig``."""
    dtype = rig.K.dtype
    M = rig.num_views
    k_rot, k_shift = jax.random.split(key)
    # Each component has std RMS / √3, so the vector's RMS length is the option's value.
    per_axis = 1.0 / math.sqrt(3.0)
    rotvec = (
        jnp.deg2rad(jnp.asarray(realism.rotation_deg, dtype))
        * per_axis
        * jax.random.normal(k_rot, (M, 3), dtype)
    )
    shift = (
        jnp.asarray(realism.translation, dtype)
        * per_axis
        * jax.random.normal(k_shift, (M, 3), dtype)
    )
    R = jnp.einsum("mij,mjk->mik", so3_exp(rotvec), rig.R)
    centers = rig.centers + shift  # (M, 3)
    t = -jnp.einsum("mij,mj->mi", R, centers)
    return Rig(rig.K, R, t)
