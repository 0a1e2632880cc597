"""Lens distortion: OpenCV's radial + tangential model, ``dist = (k1, k2, p1, p2, k3)``, and
OpenCV's fisheye model (``cv2.fisheye``), ``Fisheye(coeffs = (k1, k2, k3, k4))``.

Distortion acts on normalised camera coordinates ``(X/Z, Y/Z)``. With a general
upper-triangular ``K`` (docs/CONVENTIONS.md §1: ``K[2,2]`` may be -1), ``K / K[2,2]`` maps ``(X/Z, Y/Z, 1)``
to the same pixel as ``K``, so we normalise with ``K / K[2,2]`` (the same as applying
``K⁻¹`` and dividing by the third coordinate). For ``r² = x² + y²``::

    radial = 1 + k1 r² + k2 r⁴ + k3 r⁶
    x_d = x radial + 2 p1 x y + p2 (r² + 2 x²)
    y_d = y radial + p1 (r² + 2 y²) + 2 p2 x y

The fisheye model (equidistant with a polynomial in the angle): for ``r = √(x² + y²)`` and
``θ = atan r``::

    θ_d = θ (1 + k1 θ² + k2 θ⁴ + k3 θ⁶ + k4 θ⁸)
    (x_d, y_d) = (θ_d / r) (x, y)

A plain ``(M, 5)`` array is the first model; a :class:`Fisheye` the second (the type is
static under ``jit``, so each model compiles on its own).

Every function takes one scene's ``(M, …)`` arrays; extra leading axes ``*B`` are allowed
if all three arguments carry them, and ``jax.vmap`` works as usual.
"""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jax import lax

from .._expect import ARRAY, INT, expect_args
from .._types import Array, Bool, Float
from ._camera import Rig


class Fisheye(eqx.Module):
    """OpenCV's fisheye lens model (``cv2.fisheye``) of every view.

    Attributes:
        coeffs: ``(M, 4)`` coefficients ``(k1, k2, k3, k4)`` (OpenCV's ``D``) of every view;
            a batch adds leading axes. NumPy (host) or JAX arrays.
    """

    coeffs: Array | np.ndarray

    def __check_init__(self):
        if np.ndim(self.coeffs) < 2 or np.shape(self.coeffs)[-1] != 4:
            raise ValueError(
                f"Fisheye.coeffs must have shape (M, 4) = (k1, k2, k3, k4) per view; got {np.shape(self.coeffs)}"
            )


def _check(K, dist, xy) -> None:
    if K.shape[-2:] != (3, 3):
        raise ValueError(f"K must have shape (M, 3, 3); got {K.shape}")
    M = K.shape[-3]
    if isinstance(dist, Fisheye):
        if np.shape(dist.coeffs)[-2:] != (M, 4):
            raise ValueError(
                f"Fisheye.coeffs must have shape (M, 4) = (k1, k2, k3, k4) per view with M={M}; got {np.shape(dist.coeffs)}"
            )
    elif dist.shape[-2:] != (M, 5):
        raise ValueError(
            f"dist must have shape (M, 5) = (k1, k2, p1, p2, k3) per view with M={M}; got {dist.shape}"
        )
    if xy.ndim < 3 or xy.shape[-3] != M or xy.shape[-1] != 2:
        raise ValueError(f"xy must have shape (M, P, 2) with M={M} from K; got {xy.shape}")


def _intrinsics(K):
    """``(fx, s, cx, fy, cy)`` of ``K / K[2,2]``, each ``(*B, M, 1)`` (broadcasts over P)."""
    Kn = K / K[..., 2:3, 2:3]
    return tuple(Kn[..., i, j][..., None] for i, j in ((0, 0), (0, 1), (0, 2), (1, 1), (1, 2)))


def _normalise(K, xy):
    """Pixels ``(*B, M, P, 2)`` → normalised coordinates ``(x, y)``, each ``(*B, M, P)``."""
    fx, s, cx, fy, cy = _intrinsics(K)
    y = (xy[..., 1] - cy) / fy
    x = (xy[..., 0] - cx - s * y) / fx
    return x, y


def _shift_pixels(K, xy, dx, dy):
    """``xy (*B, M, P, 2)`` moved by the normalised offset ``(dx, dy)`` (each ``(*B, M, P)``).

    Adding the offset to the input pixel, rather than mapping the new normalised point back
    through ``K``, keeps the pixel's own precision and makes zero distortion exactly the
    identity.
    """
    fx, s, _, fy, _ = _intrinsics(K)
    return xy + jnp.stack([fx * dx + s * dy, fy * dy], axis=-1)


def _coefficients(dist):
    """``(k1, k2, p1, p2, k3)``, each ``(*B, M, 1)``."""
    return tuple(dist[..., i][..., None] for i in range(5))


def _displacement(dist, x, y):
    """OpenCV's model as an offset: ``distorted − ideal`` of the normalised point ``(x, y)``.

    Exactly 0 for zero coefficients, whatever the rounding of ``(x, y)``.
    """
    k1, k2, p1, p2, k3 = _coefficients(dist)
    r2 = x * x + y * y
    radial_m1 = r2 * (k1 + r2 * (k2 + r2 * k3))  # radial − 1
    dx = x * radial_m1 + 2 * p1 * x * y + p2 * (r2 + 2 * x * x)
    dy = y * radial_m1 + p1 * (r2 + 2 * y * y) + 2 * p2 * x * y
    return dx, dy


def _newton_step(dist, xd, yd, ox, oy):
    """One Newton step on the offset ``o = ideal − distorted`` (normalised) solving
    ``o + displacement(x_d + o) = 0``, with the analytic 2×2 Jacobian ``I + ∂displacement``.

    Where the Jacobian is (nearly) singular or the step is not finite, the offset stays
    put, so garbage in padded slots can never turn into NaN.
    """
    k1, k2, p1, p2, k3 = _coefficients(dist)
    x, y = xd + ox, yd + oy
    r2 = x * x + y * y
    radial = 1 + r2 * (k1 + r2 * (k2 + r2 * k3))
    g = k1 + r2 * (2 * k2 + 3 * k3 * r2)  # d radial / d r²
    dx, dy = _displacement(dist, x, y)
    ex, ey = ox + dx, oy + dy
    j11 = radial + 2 * x * x * g + 2 * p1 * y + 6 * p2 * x
    j12 = 2 * x * y * g + 2 * p1 * x + 2 * p2 * y  # the Jacobian is symmetric: j21 = j12
    j22 = radial + 2 * y * y * g + 6 * p1 * y + 2 * p2 * x
    det = j11 * j22 - j12 * j12
    ok = jnp.abs(det) > jnp.finfo(det.dtype).eps
    inv_det = 1 / jnp.where(ok, det, 1.0)
    step_x = (j22 * ex - j12 * ey) * inv_det
    step_y = (j11 * ey - j12 * ex) * inv_det
    ok = ok & jnp.isfinite(step_x) & jnp.isfinite(step_y)
    return jnp.where(ok, ox - step_x, ox), jnp.where(ok, oy - step_y, oy)


def distort_pixels(
    K: Float[Array, "*B M 3 3"],
    dist: Float[Array, "*B M 5"] | Fisheye,
    xy: Float[Array, "*B M P 2"],
) -> Float[Array, "*B M P 2"]:
    """Ideal (undistorted) pixels → distorted pixels, OpenCV's model, per view.

    Args:
        K: ``(M, 3, 3)`` intrinsics, general upper-triangular (``K[2,2]`` may be -1).
        dist: ``(M, 5)`` coefficients ``(k1, k2, p1, p2, k3)`` of every view, or a
            :class:`Fisheye` of ``(M, 4)`` coefficients.
        xy: ``(M, P, 2)`` ideal pixels.

    Returns:
        ``(M, P, 2)`` distorted pixels (what a real camera records). Zero ``dist`` returns
        ``xy`` exactly.
    """
    expect_args("distort_pixels", K=(K, ARRAY), xy=(xy, ARRAY))
    _check_dist_type("distort_pixels", dist)
    _check(K, dist, xy)
    x, y = _normalise(K, xy)
    if isinstance(dist, Fisheye):
        return _shift_pixels(
            K, xy, *_fisheye_displacement(jnp.asarray(dist.coeffs, xy.dtype), x, y)
        )
    return _shift_pixels(K, xy, *_displacement(dist, x, y))


def undistort_pixels(
    K: Float[Array, "*B M 3 3"],
    dist: Float[Array, "*B M 5"] | Fisheye,
    xy: Float[Array, "*B M P 2"],
    *,
    iterations: int = 20,
) -> Float[Array, "*B M P 2"]:
    """Distorted pixels → ideal pixels: the inverse of :func:`distort_pixels`.

    Solved per point in normalised coordinates with ``iterations`` (static) Newton steps
    from the distorted point itself, then one differentiable Newton step that carries the
    gradients (implicit-function derivative) w.r.t. ``K``, ``dist`` and ``xy``.

    Args:
        K: ``(M, 3, 3)`` intrinsics, general upper-triangular (``K[2,2]`` may be -1).
        dist: ``(M, 5)`` coefficients ``(k1, k2, p1, p2, k3)`` of every view, or a
            :class:`Fisheye` of ``(M, 4)`` coefficients.
        xy: ``(M, P, 2)`` distorted (recorded) pixels; padded slots may hold anything
            finite (e.g. 0) and stay finite.
        iterations: number of Newton steps (a Python int, static under ``jit``).

    Returns:
        ``(M, P, 2)`` ideal pixels, those that :func:`distort_pixels` maps onto ``xy``.
    """
    expect_args("undistort_pixels", K=(K, ARRAY), xy=(xy, ARRAY), iterations=(iterations, INT))
    _check_dist_type("undistort_pixels", dist)
    _check(K, dist, xy)
    if not isinstance(iterations, int) or iterations < 0:
        raise ValueError(f"iterations must be a non-negative Python int; got {iterations!r}")
    xd, yd = _normalise(K, xy)
    if isinstance(dist, Fisheye):
        return _shift_pixels(
            K,
            xy,
            *_fisheye_undistort_offset(jnp.asarray(dist.coeffs, xy.dtype), xd, yd, iterations),
        )

    # Newton with the 2×2 Jacobian rather than OpenCV's fixed point x ← (x_d − tangential) /
    # radial: the fixed point converges linearly with the factor |r ρ'(r) / ρ(r)| (ρ = radial),
    # which tends to 1 where the model nears its fold (dr_d/dr → 0). Measured to 1e-3 px at an
    # f = 400 image corner (r = 1): k1 = -0.3 needs 68 fixed-point steps and 5 Newton steps;
    # k1 = -0.3, k2 = 0.1 at f = 500: 9 and 3. Newton converges quadratically wherever the
    # model is invertible (det J > 0), so 20 steps leave only rounding in float32 and float64.
    # Unknown: the offset o = ideal − distorted, starting at 0, so that zero distortion is
    # exactly the identity. The loop runs on constants (stop_gradient): differentiating
    # through the unrolled steps would be costly and only approximate the derivative.
    dist_c, xd_c, yd_c = (lax.stop_gradient(a) for a in (dist, xd, yd))

    def body(_, o):
        return _newton_step(dist_c, xd_c, yd_c, *o)

    zero = jnp.zeros_like(xd_c)
    ox, oy = lax.fori_loop(0, iterations, body, (zero, zero))
    # At the solution o* one more Newton step, o* − J⁻¹ (o* + displacement(x_d + o*)), is the
    # identity in value, and its derivative w.r.t. (dist, x_d) is exactly the implicit-function
    # derivative (the terms multiplied by the residual vanish).
    ox, oy = _newton_step(dist, xd, yd, lax.stop_gradient(ox), lax.stop_gradient(oy))
    return _shift_pixels(K, xy, ox, oy)


def as_lens(dist, dtype):
    """``dist`` (array-like ``(M, 5)`` or a :class:`Fisheye`) as JAX arrays of ``dtype``."""
    if isinstance(dist, Fisheye):
        return Fisheye(jnp.asarray(dist.coeffs, dtype))
    return jnp.asarray(dist, dtype)


def _check_dist_type(function: str, dist) -> None:
    if isinstance(dist, Fisheye):
        expect_args(function, **{"dist.coeffs": (dist.coeffs, ARRAY)})
    else:
        expect_args(function, dist=(dist, ARRAY))


# OpenCV's fisheye model -------------------------------------------------------------------


def _theta_d(k, theta):
    """``θ (1 + k1 θ² + k2 θ⁴ + k3 θ⁶ + k4 θ⁸)`` and its derivative in ``θ``."""
    k1, k2, k3, k4 = (k[..., i][..., None] for i in range(4))
    t2 = theta * theta
    poly = t2 * (k1 + t2 * (k2 + t2 * (k3 + t2 * k4)))
    slope = 1 + t2 * (3 * k1 + t2 * (5 * k2 + t2 * (7 * k3 + t2 * 9 * k4)))
    return theta * (1 + poly), slope


def _fisheye_displacement(k, x, y):
    """``distorted − ideal`` of the normalised point ``(x, y)`` under the fisheye model."""
    r2 = x * x + y * y
    pos = r2 > 0
    r = jnp.sqrt(jnp.where(pos, r2, 1.0))  # no infinite derivative at the centre
    theta_d, _ = _theta_d(k, jnp.arctan(r))
    scale_m1 = jnp.where(pos, theta_d / r - 1, 0.0)  # θ_d / r → 1 at the centre
    return x * scale_m1, y * scale_m1


def _fisheye_undistort_offset(k, xd, yd, iterations: int):
    """``ideal − distorted`` (normalised) under the fisheye model: Newton on
    ``θ_d(θ) = |(x_d, y_d)|`` from ``θ = θ_d``, then one differentiable step (the
    implicit-function derivative, as for the other model); ``r = tan θ``.

    A step that is not finite or whose slope is not positive (past the model's fold) is
    not taken, so every output stays finite.
    """
    rd2 = xd * xd + yd * yd
    pos = rd2 > 0
    rd = jnp.sqrt(jnp.where(pos, rd2, 1.0))

    def step(k, rd, theta):
        value, slope = _theta_d(k, theta)
        new = theta - (value - rd) / jnp.where(slope > 0, slope, 1.0)
        ok = (slope > 0) & jnp.isfinite(new)
        return jnp.where(ok, new, theta)

    k_c, rd_c = lax.stop_gradient(k), lax.stop_gradient(rd)
    theta = lax.fori_loop(0, iterations, lambda _, th: step(k_c, rd_c, th), rd_c)
    theta = step(k, rd, lax.stop_gradient(theta))
    # θ below π/2 keeps tan θ finite; a point beyond is not an image of this lens.
    theta = jnp.clip(theta, 0.0, jnp.pi / 2 - 1e-3)
    scale_m1 = jnp.where(pos, jnp.tan(theta) / rd - 1, 0.0)
    return xd * scale_m1, yd * scale_m1


def undistorted(
    rig: Rig,
    xy: Float[Array, "M P 2"],
    mask: Bool[Array, "M P"],
    dist: Float[Array, "M 5"] | Fisheye,
) -> Float[Array, "M P 2"]:
    """Detections ``xy (M, P, 2)`` (pixels, as the lens saw them) mapped to the ideal pinhole
    pixels of ``rig`` through OpenCV distortion ``dist (M, 5)`` or a :class:`Fisheye`;
    padding stays 0."""
    return jnp.where(
        mask[..., None], undistort_pixels(rig.K, dist, jnp.where(mask[..., None], xy, 0.0)), 0.0
    )


LENS_RESIDUAL_PX = 0.1
"""How far (pixels) the lens may map an undistorted detection from where it was seen before
the undistortion counts as failed: a fraction of any detector's noise, far above the
round-off of a converged inversion."""


def undistorted_checked(
    rig: Rig,
    xy: Float[Array, "M P 2"],
    mask: Bool[Array, "M P"],
    dist: Float[Array, "M 5"] | Fisheye,
) -> tuple[Float[Array, "M P 2"], Bool[Array, ""]]:
    """:func:`undistorted`, and whether the inversion failed at any detection: its result
    distorted again lands more than :data:`LENS_RESIDUAL_PX` from the detection (or is not
    finite), as where the model folds the image (a large negative ``k1``: no ideal pixel maps
    there, and the Newton steps stop anywhere)."""
    ideal = undistorted(rig, xy, mask, dist)
    miss = jnp.linalg.norm(distort_pixels(rig.K, dist, ideal) - xy, axis=-1)  # (M, P)
    bad = ~(miss <= LENS_RESIDUAL_PX)
    if not isinstance(dist, Fisheye):
        bad = bad | _folded(dist, *_normalise(rig.K, ideal))
    return ideal, jnp.any(mask & bad)


def _folded(dist, x, y, samples: int = 8):
    """``(M, P)``: the radial model is not increasing all the way from the centre to the
    ideal point ``(x, y)`` (normalised): the distorted radius ``r (1 + k1 r² + k2 r⁴ + k3 r⁶)``
    turns back before it (its derivative ``1 + 3 k1 r² + 5 k2 r⁴ + 7 k3 r⁶ ≤ 0``), so a second
    ideal point has the same detection and the inversion may have found either."""
    k1, k2, _, _, k3 = _coefficients(dist)
    r2 = x * x + y * y
    folded = jnp.zeros(r2.shape, bool)
    for k in range(1, samples + 1):  # the radii r·k/samples, the last the point's own
        q = r2 * (k / samples) ** 2
        folded = folded | (1.0 + q * (3.0 * k1 + q * (5.0 * k2 + q * 7.0 * k3)) <= 0.0)
    return folded


undistorted_frames = jax.jit(jax.vmap(undistorted, in_axes=(None, 0, 0, None)))
""":func:`undistorted` of every frame, ``xy (F, M, P, 2)`` → same, as one compiled program
(run eagerly, its Newton loop would be compiled again on every call)."""
