"""Camera refinement from associations: a joint Levenberg–Marquardt fit of the
cameras and the 3D points of the groups of ``S`` scenes seen by one rig (alternated with
association in ``_calibrate.py``; rigs compared in ``_alignment.py``).

Gauge. Pixels do not change under a similarity transform of the world (7 DoF), so the
refinement fixes one: camera 0's rotation and translation are not unknowns, and camera
1's centre moves on the sphere about camera 0's centre through its starting position
(2 DoF: a rotation of the baseline direction about an axis normal to it), so the baseline
length, hence the scale, keeps its starting value. A parameterisation rather than a stiff
penalty: it is exact, has no weight to tune and leaves the normal equations as well
conditioned as they are (float32 included). The intrinsics of every view, view 0
included, are free when enabled. A refined rig therefore agrees with the truth only up to
that gauge; compare rigs after :func:`align_rigs`.

Solver. ``optx.LevenbergMarquardt`` (its trust-region damping and termination) whose
damped Gauss–Newton step is solved with the points eliminated by the Schur complement, as
bundle adjustment does; the unknowns are the free camera parameters and, per scene, the
points of at most ``max_groups`` groups (a static capacity).
"""

from __future__ import annotations

import functools
from typing import NamedTuple

import equinox as eqx
import jax
import jax.flatten_util
import jax.numpy as jnp
import optimistix as optx
from jaxtyping import ArrayLike, Real

from .._expect import ARRAY, expect_args
from .._types import Array, Bool, Float, Int
from ..geometry._camera import Rig
from ..geometry._parameters import CameraParams, params_from_rig, rig_from_params, so3_exp
from ..geometry._projection import project_views_last
from ..geometry._triangulate import triangulate_views_last
from ..graph._groups import gather_groups
from ._bpe_loss import _LOSSES, Loss, _rho, group_bpe


class RefineInfo(NamedTuple):
    """What :func:`refine_rig` reports (a batch of rigs adds leading axes).

    Attributes:
        bpe_before: ``()`` mean squared reprojection error (px²) over the members of the
            used groups, starting rig and DLT points.
        bpe_after: ``()`` the same at the returned rig and refined points (equal to
            ``bpe_before`` when the refinement was rejected).
        num_steps: ``()`` int, Levenberg–Marquardt steps taken.
        converged: ``()`` bool, the solver met its tolerance within ``max_steps``.
        accepted: ``()`` bool, the refinement lowered the cost and was kept.
        num_groups: ``()`` int, groups used, summed over scenes.
    """

    bpe_before: Float[Array, ""]
    bpe_after: Float[Array, ""]
    num_steps: Int[Array, ""]
    converged: Bool[Array, ""]
    accepted: Bool[Array, ""]
    num_groups: Int[Array, ""]


class _Start(eqx.Module):
    """The starting rig in the form the unknowns are increments of."""

    rig: Rig
    params: CameraParams  # intrinsics normalised to K[2, 2] = 1
    centers: Float[Array, "M 3"]
    baseline: Float[Array, ""]  # ‖C_1 − C_0‖
    direction: Float[Array, " 3"]  # (C_1 − C_0) / baseline
    tangent: Float[Array, "2 3"]  # orthonormal basis normal to `direction`
    f_scale: Float[Array, " M"]  # |f| per view (pixels), the unit of c and skew increments


class _CameraUnknowns(eqx.Module):
    """The free camera parameters: increments from :class:`_Start` (``None``: fixed)."""

    rotvec: Float[Array, "M1 3"]  # R_m = exp([w_m]×) R_m⁰ for views 1..M-1 (radians)
    baseline: Float[Array, " 2"]  # C_1 = C_0 + b exp([u₁ e₁ + u₂ e₂]×) d (radians)
    centers: Float[Array, "M2 3"]  # C_m = C_m⁰ + δ for views 2..M-1 (scene units)
    focal: Float[Array, "M 2"] | None  # f = f⁰ (1 + δ)
    principal: Float[Array, "M 2"] | None  # c = c⁰ + |f⁰| δ
    skew: Float[Array, " M"] | None  # s = s⁰ + |f⁰| δ


def _start(rig: Rig) -> _Start:
    params = params_from_rig(rig)
    C = rig.centers
    v = C[1] - C[0]
    b = jnp.sqrt(jnp.sum(v * v))
    d = v / b
    # The world axis least aligned with d gives a well-conditioned normal pair.
    axis = jnp.eye(3, dtype=C.dtype)[jnp.argmin(jnp.abs(d))]
    e1 = jnp.cross(d, axis)
    e1 = e1 / jnp.sqrt(jnp.sum(e1 * e1))
    tangent = jnp.stack([e1, jnp.cross(d, e1)])
    f_scale = jnp.mean(jnp.abs(params.focal), axis=-1)
    return _Start(rig, params, C, b, d, tangent, f_scale)


def _rig_from_unknowns(start: _Start, u: _CameraUnknowns) -> Rig:
    """The rig of the unknowns; camera 0's ``R, t`` (and ``K`` when fixed) are the start's."""
    R0, t0 = start.rig.R, start.rig.t
    R_free = jnp.einsum("mij,mjk->mik", so3_exp(u.rotvec), R0[1:])
    C1 = start.centers[0] + start.baseline * (so3_exp(u.baseline @ start.tangent) @ start.direction)
    C_free = jnp.concatenate([C1[None], start.centers[2:] + u.centers])  # (M-1, 3)
    R = jnp.concatenate([R0[:1], R_free])
    t = jnp.concatenate([t0[:1], -jnp.einsum("mij,mj->mi", R_free, C_free)])
    if u.focal is None:
        return Rig(start.rig.K, R, t)
    p0, scale = start.params, start.f_scale[:, None]
    principal = p0.principal if u.principal is None else p0.principal + scale * u.principal
    skew = p0.skew if u.skew is None else p0.skew + start.f_scale * u.skew
    params = CameraParams(p0.rotvec, p0.t, p0.focal * (1.0 + u.focal), principal, skew)
    return Rig(rig_from_params(params).K, R, t)  # only K is read from rig_from_params


def _robust_weight(s: Float[Array, "*S"], loss: str, c: Float[Array, ""]) -> Float[Array, "*S"]:
    """``sqrt(ρ(s) / s)``, so that a weighted residual ``w r`` has ``‖w r‖² = ρ(‖r‖²)``."""
    if loss == "l2":
        return jnp.ones_like(s)
    pos = s > 0
    s_safe = jnp.where(pos, s, 1.0)  # ρ(s)/s → 1 at s = 0 for every kernel; keep 0/0 out
    rho = _rho(s_safe, loss, c)
    return jnp.where(pos, jnp.sqrt(rho / s_safe), 1.0)


class _SchurState(eqx.Module):
    """Blocks of ``JᵀJ`` and ``Jᵀr`` at the current iterate (cameras ``c``, points ``p``)."""

    U: Float[Array, "C C"]  # J_cᵀ J_c
    W: Float[Array, "N C 3"]  # J_cᵀ J_p, per point
    V: Float[Array, "N 3 3"]  # J_pᵀ J_p, per point
    g_c: Float[Array, " C"]
    g_p: Float[Array, "S K 3"]


class _SchurDampedNewton(optx.AbstractDescent):
    """The Levenberg–Marquardt step ``(JᵀJ + λI) δ = −Jᵀr``, ``λ = 1 / step_size`` (what
    ``optx.LevenbergMarquardt``'s damped Newton descent solves), with the points
    eliminated by the Schur complement as in bundle adjustment.

    The unknowns are ``(camera vector (C,), points (S, K, 3))`` and the residuals
    ``(S, K, M, 2)``, row ``[s, k]`` depending on point ``[s, k]`` only; so all points'
    Jacobians come from 3 products (one per coordinate) and the camera columns from ``C``.
    A dense QR of the whole Jacobian (optimistix's default) costs ``O(rows · (C + 3SK)²)``
    per step, this ``O(rows · C²)``: measured on 2 CPU cores, 4 scenes × 64 groups, 0.05 s
    per refinement instead of 7 s.
    """

    def init(self, y, f_info_struct):
        cam, points = y
        C, N = cam.shape[0], points.shape[0] * points.shape[1]
        zeros = functools.partial(jnp.zeros, dtype=cam.dtype)
        return _SchurState(
            zeros((C, C)), zeros((N, C, 3)), zeros((N, 3, 3)), zeros((C,)), zeros(points.shape)
        )

    def query(self, y, f_info, state):
        del state
        cam, points = y
        C, N = cam.shape[0], points.shape[0] * points.shape[1]
        mv = f_info.jac.mv
        J_c = jax.vmap(lambda e: mv((e, jnp.zeros_like(points))))(jnp.eye(C, dtype=cam.dtype))
        J_p = jax.vmap(lambda e: mv((jnp.zeros_like(cam), jnp.broadcast_to(e, points.shape))))(
            jnp.eye(3, dtype=cam.dtype)
        )
        J_c, J_p = J_c.reshape(C, N, -1), J_p.reshape(3, N, -1)  # (C | 3, N, 2M)
        r = f_info.residual.reshape(N, -1)
        return _SchurState(
            U=jnp.einsum("anr,bnr->ab", J_c, J_c),
            W=jnp.einsum("anr,jnr->naj", J_c, J_p),
            V=jnp.einsum("inr,jnr->nij", J_p, J_p),
            g_c=jnp.einsum("anr,nr->a", J_c, r),
            g_p=jnp.einsum("inr,nr->ni", J_p, r).reshape(points.shape),
        )

    def step(self, step_size, state):
        U, W, V, g_c = state.U, state.W, state.V, state.g_c
        g_p = state.g_p.reshape(-1, 3)
        # As optimistix does: λ = 1 / step_size, bounded where the step size underflows.
        lam = 1.0 / jnp.maximum(step_size, jnp.finfo(U.dtype).eps)
        V_inv = jnp.linalg.inv(V + lam * jnp.eye(3, dtype=U.dtype)[None])  # (N, 3, 3)
        WV = jnp.einsum("naj,njk->nak", W, V_inv)  # (N, C, 3)
        S = U + lam * jnp.eye(U.shape[0], dtype=U.dtype) - jnp.einsum("naj,nbj->ab", WV, W)
        d_c = jnp.linalg.solve(S, g_c - jnp.einsum("naj,nj->a", WV, g_p))
        d_p = jnp.einsum("nij,nj->ni", V_inv, g_p - jnp.einsum("naj,a->nj", W, d_c))
        return (-d_c, -d_p.reshape(state.g_p.shape)), optx.RESULTS.successful


def _select_groups(rig, xy, groups, valid, max_groups):
    """One scene's ``max_groups`` best groups: most views first, ties by lowest BPE.

    Returns ``xy_g (K, M, 2)``, ``member (K, M)`` (False on unused rows) and the DLT points
    ``X (K, 3)`` with the starting rig.
    """
    P = xy.shape[1]
    member = valid[:, None] & (groups >= 0) & (groups < P)  # (G, M)
    xy_g = gather_groups(groups, xy)  # (G, M, 2); out-of-range slots are clamped, then masked
    xy_g = jnp.where(member[..., None], xy_g, 0.0)
    X, ok = triangulate_views_last(rig, xy_g, member)
    n_views = jnp.sum(member, axis=1, dtype=jnp.int32)
    usable = valid & ok & (n_views >= 2)
    err = group_bpe(rig, xy, groups, usable, points3d=X)
    err = jnp.where(usable & jnp.isfinite(err), err, jnp.inf)
    order = jnp.lexsort((err, -jnp.where(usable, n_views, -1)))[:max_groups]
    return xy_g[order], member[order] & usable[order, None], X[order]


def _check_options(M, max_groups, loss, refine_intrinsics, refine_principal, refine_skew):
    if M < 2:
        raise ValueError(
            f"refinement needs at least 2 views (the gauge uses cameras 0 and 1); got M={M}"
        )
    if not isinstance(max_groups, int) or max_groups < 1:
        raise ValueError(f"max_groups must be a Python int >= 1; got {max_groups!r}")
    if loss not in _LOSSES:
        raise ValueError(f"loss must be one of {_LOSSES}; got {loss!r}")
    if (refine_principal or refine_skew) and not refine_intrinsics:
        raise ValueError("refine_principal and refine_skew need refine_intrinsics=True")


def _check_xy(rig: Rig, xy) -> None:
    M = rig.K.shape[-3]
    if xy.ndim != 4 or xy.shape[1] != M or xy.shape[3] != 2:
        raise ValueError(f"xy must have shape (S, M, P, 2) with M={M} from the rig; got {xy.shape}")
    if xy.dtype != rig.K.dtype:
        raise ValueError(f"xy and the rig must share a dtype; got {xy.dtype} and {rig.K.dtype}")


def refine_rig(
    rig: Rig,
    xy: Float[Array, "S M P 2"],
    groups: Int[Array, "S G M"],
    valid: Bool[Array, "S G"],
    *,
    max_groups: int = 64,
    refine_intrinsics: bool = True,
    refine_principal: bool = False,
    refine_skew: bool = False,
    loss: Loss = "l2",
    scale_px: Real[ArrayLike, ""] = 2.0,
    max_steps: int = 50,
) -> tuple[Rig, RefineInfo]:
    """Refine a rig jointly with the 3D points of associated groups (Levenberg–Marquardt).

    Per scene, only the ``max_groups`` valid groups with the most views (ties: lowest BPE)
    inform the calibration; their DLT points with the starting rig start the fit. The
    unknowns are the rotations and centres of views 1..M-1 under the gauge of the module
    docstring, the focal lengths (and optionally principal points and skews) of all views,
    and the points. Residuals are member reprojection errors in pixels, each scaled by
    ``sqrt(ρ(s)/s)`` for a robust ``loss`` (``ρ`` as :func:`group_bpe`, scale ``scale_px``).
    The result is kept only if it lowers that cost (and is finite); otherwise ``rig`` is
    returned unchanged. A refined ``K`` is normalised to ``K[2, 2] = 1`` (same pixels).

    Args:
        rig: ``M`` cameras shared by the scenes (``M ≥ 2``).
        xy: ``(S, M, P, 2)`` detections (pixels) of ``S`` scenes.
        groups: ``(S, G, M)`` int slot of each group's member per view, -1 for none.
        valid: ``(S, G)`` bool, row holds a group.
        max_groups: static capacity of groups used per scene.
        refine_intrinsics: static; free focal lengths. ``refine_principal`` and
            ``refine_skew`` (static) free the principal points and skews as well.
        loss: static ``"l2"``, ``"huber"`` or ``"cauchy"``; ``scale_px`` its scale (may be traced).
        max_steps: static bound on solver steps.

    Returns:
        The refined :class:`Rig` and a :class:`RefineInfo`. Jit with these options static;
        ``jax.vmap`` over rigs (``in_axes=(0, None, None, None)``) works.
    """
    expect_args(
        "refine_rig", rig=(rig, Rig), xy=(xy, ARRAY), groups=(groups, ARRAY), valid=(valid, ARRAY)
    )
    _check_xy(rig, xy)
    S, M = xy.shape[0], xy.shape[1]
    if groups.ndim != 3 or groups.shape[0] != S or groups.shape[2] != M:
        raise ValueError(f"groups must have shape (S={S}, G, M={M}); got {groups.shape}")
    if valid.shape != groups.shape[:2]:
        raise ValueError(f"valid must have shape (S, G) = {groups.shape[:2]}; got {valid.shape}")
    _check_options(M, max_groups, loss, refine_intrinsics, refine_principal, refine_skew)
    return _refine_rig(
        rig,
        xy,
        groups,
        valid,
        jnp.asarray(scale_px, xy.dtype),
        max_groups=max_groups,
        refine_intrinsics=refine_intrinsics,
        refine_principal=refine_principal,
        refine_skew=refine_skew,
        loss=loss,
        max_steps=max_steps,
    )


_STATIC = (
    "max_groups",
    "refine_intrinsics",
    "refine_principal",
    "refine_skew",
    "loss",
    "max_steps",
)


# Jitted here so that eager calls compile once; under an outer jit or vmap it is inlined.
@functools.partial(jax.jit, static_argnames=_STATIC)
def _refine_rig(
    rig,
    xy,
    groups,
    valid,
    scale_px,
    *,
    max_groups,
    refine_intrinsics,
    refine_principal,
    refine_skew,
    loss,
    max_steps,
):
    M = rig.K.shape[-3]
    dtype = xy.dtype
    select = functools.partial(_select_groups, max_groups=min(max_groups, groups.shape[1]))
    xy_g, member, X0 = jax.vmap(select, in_axes=(None, 0, 0, 0))(
        rig, xy, groups, valid
    )  # (S, K, ...)

    start = _start(rig)
    zeros = functools.partial(jnp.zeros, dtype=dtype)
    cam0, unravel = jax.flatten_util.ravel_pytree(
        _CameraUnknowns(
            rotvec=zeros((M - 1, 3)),
            baseline=zeros((2,)),
            centers=zeros((M - 2, 3)),
            focal=zeros((M, 2)) if refine_intrinsics else None,
            principal=zeros((M, 2)) if refine_principal else None,
            skew=zeros((M,)) if refine_skew else None,
        )
    )
    y0 = (cam0, X0)

    def errors(y):
        cam, X = y
        xy_hat, _ = project_views_last(_rig_from_unknowns(start, unravel(cam)), X)  # (S, K, M, 2)
        d = jnp.where(member[..., None], xy_hat - xy_g, 0.0)
        return d, jnp.sum(d * d, axis=-1)  # px, px²

    def residuals(y, _):
        d, s = errors(y)
        return d * _robust_weight(s, loss, scale_px)[..., None]

    def cost(y):
        r = residuals(y, None)
        return jnp.sum(r * r)

    # Steps shrink quadratically near the optimum, so stopping once a step is below
    # sqrt(eps) (relative to the unknowns and the residuals) leaves the answer near eps.
    tol = float(jnp.finfo(dtype).eps) ** 0.5
    solver = eqx.tree_at(
        lambda s: s.descent, optx.LevenbergMarquardt(rtol=tol, atol=tol), _SchurDampedNewton()
    )
    sol = optx.least_squares(residuals, solver, y0, max_steps=max_steps, throw=False)

    finite = jnp.all(jnp.isfinite(sol.value[0])) & jnp.all(jnp.isfinite(sol.value[1]))
    accepted = finite & (cost(sol.value) < cost(y0))
    y = jax.tree_util.tree_map(lambda a, b: jnp.where(accepted, a, b), sol.value, y0)
    refined = _rig_from_unknowns(start, unravel(y[0]))
    out = jax.tree_util.tree_map(lambda a, b: jnp.where(accepted, a, b), refined, rig)

    count = jnp.maximum(jnp.sum(member, dtype=dtype), 1.0)
    info = RefineInfo(
        bpe_before=jnp.sum(errors(y0)[1]) / count,
        bpe_after=jnp.sum(errors(y)[1]) / count,
        num_steps=jnp.asarray(sol.stats["num_steps"], jnp.int32),
        converged=sol.result == optx.RESULTS.successful,
        accepted=accepted,
        num_groups=jnp.sum(jnp.any(member, axis=-1), dtype=jnp.int32),
    )
    return out, info
