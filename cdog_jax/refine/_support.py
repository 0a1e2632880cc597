"""Visibility support of a group (beyond the paper; ``Config.support_filter``).

A real point is detected in (nearly) every view that sees it; a group made of clutter, or
of clutter and a stray detection, triangulates to a point that other views should see but
where they hold no detection. For every group, a view is *missing* when it is not a member
view, the group's point is in front of its camera and projects inside the view's
detection area, and no detection of the view lies within ``support_frac · τ`` pixels of the
projection. Missed detections make real points miss views too, so the test is a binomial
one: with ``q`` the scene's miss rate, estimated as the share of missing views over the
groups with ≥ ``support_ref_views`` members (at least ``support_min_rate``), a group of
``n`` members and ``k`` missing views is dropped when ``P(Bin(n + k, q) ≥ k) <
support_alpha``, i.e. when that many misses are implausible at that rate; and when its point
is behind one of its member cameras. Without drops ``q`` is about 0 (floored at 0.02) and
two missing views already drop a small group (2 members: P ≈ 0.002); at ``q = 0.25`` a
2-view group is kept with up to 5 missing views (P(Bin(7, 0.25) ≥ 5) ≈ 0.013).

The pipeline is not told the image size: a view's detection area is the bounding box of
its valid detections (with clutter it is about the whole image; without it, the region
where points are seen). Views without a detection never count as missing.
"""

import jax
import jax.numpy as jnp
from jaxtyping import ArrayLike

from .._types import Array, Bool, Float, Int
from ..cdog._config import Range, Switch, Threshold, ThresholdsBase
from ..cdog._stage import Scene, Stage, State
from ..geometry._camera import Rig
from ..geometry._projection import project_views_last


def missing_views(
    rig: Rig,
    xy: Float[Array, "M P 2"],
    mask: Bool[Array, "M P"],
    X: Float[Array, "G 3"],
    member: Bool[Array, "G M"],
    radius_px: Float[Array, ""],
) -> tuple[Bool[Array, "G M"], Bool[Array, "G M"]]:
    """``(G, M)`` views where group ``g``'s point ``X[g]`` should be detected but is not, and
    ``(G, M)`` whether it is in front of each camera."""
    pix, in_front = project_views_last(rig, X)  # (G, M, 2), (G, M)
    lo = jnp.min(jnp.where(mask[..., None], xy, jnp.inf), axis=1)  # (M, 2); +inf: no detection
    hi = jnp.max(jnp.where(mask[..., None], xy, -jnp.inf), axis=1)
    inside = in_front & jnp.all((pix >= lo[None]) & (pix <= hi[None]), axis=-1)  # (G, M)
    # x and y apart, reduced at once: seeding asks this of every two-view hypothesis.
    dx = pix[:, :, None, 0] - xy[None, :, :, 0]  # (G, M, P)
    dy = pix[:, :, None, 1] - xy[None, :, :, 1]
    nearest = jnp.min(jnp.where(mask[None], dx * dx + dy * dy, jnp.inf), axis=-1)  # (G, M) px²
    near = nearest < radius_px * radius_px
    return inside & ~member & ~near, in_front


def misses_plausible(
    k_views: Int[Array, " G"],
    T_views: Int[Array, " G"],
    q: Float[Array, ""],
    alpha: Float[ArrayLike, ""],
    num_views: int,
) -> Bool[Array, " G"]:
    """``(G,)``: ``k_views`` missing views of ``T_views`` that should detect a point are
    plausible at the miss rate ``q``: none is missing, or ``P(Bin(T, q) ≥ k) ≥ alpha``
    (``T ≤ num_views``)."""
    dtype = q.dtype
    k, T = k_views.astype(dtype), T_views.astype(dtype)
    # P(Bin(T, q) >= k): a sum of the binomial pmf over j = k … T ≤ M. Its log-factorials
    # are of whole numbers up to M: read from one table of lgamma(0 … M + 1) (the same
    # values, M + 2 evaluations instead of three per group and j); [n] = log (n − 1)!.
    M = num_views
    log_factorial = jax.lax.lgamma(jnp.arange(M + 2, dtype=dtype))
    j_views = jnp.arange(M + 1, dtype=jnp.int32)[None, :]  # (1, M + 1)
    j = j_views.astype(dtype)
    Tc, kc = T[:, None], k[:, None]
    j_ok = j <= Tc
    jT = jnp.where(j_ok, j, 0.0)
    jT_views = jnp.where(j_ok, j_views, 0)
    T_col = T_views[:, None]
    log_pmf = (
        log_factorial[T_col + 1]
        - log_factorial[jT_views + 1]
        - log_factorial[T_col - jT_views + 1]
        + jT * jnp.log(q)
        + (Tc - jT) * jnp.log1p(-q)
    )
    tail = jnp.sum(jnp.where(j_ok & (j >= kc), jnp.exp(log_pmf), 0.0), axis=1)  # (G,)
    return (k == 0) | (tail >= alpha)


def support_test(
    rig: Rig,
    xy: Float[Array, "M P 2"],
    mask: Bool[Array, "M P"],
    X: Float[Array, "G 3"],
    member: Bool[Array, "G M"],
    valid: Bool[Array, " G"],
    tau_px: Float[Array, ""],
    thresholds: ThresholdsBase,
) -> tuple[Bool[Array, " G"], Float[Array, ""]]:
    """``(keep (G,), q ())``: the valid groups that pass the visibility-support test and the
    scene's miss rate it estimated (module docstring).

    Args:
        xy, mask: the scene's detections ``(M, P, 2)`` (pixels) and ``(M, P)``.
        X: ``(G, 3)`` each group's triangulated point; ``member (G, M)`` its member views.
        valid: ``(G,)`` groups to test; the result is a subset.
    """
    M = mask.shape[0]
    dtype = xy.dtype
    member = member & valid[:, None]
    missing, in_front = missing_views(rig, xy, mask, X, member, thresholds.support_frac * tau_px)
    k_views = jnp.sum(missing, axis=1, dtype=jnp.int32)  # (G,) missing views
    T_views = k_views + jnp.sum(member, axis=1, dtype=jnp.int32)  # (G,) views that should detect
    k, T = k_views.astype(dtype), T_views.astype(dtype)
    behind = jnp.any(member & ~in_front, axis=1)

    # Miss rate of the scene, from the groups large enough to be trusted.
    ref = valid & ~behind & (T - k >= thresholds.support_ref_views)
    k_ref, T_ref = jnp.sum(jnp.where(ref, k, 0.0)), jnp.sum(jnp.where(ref, T, 0.0))
    q = jnp.where(T_ref > 0, k_ref / jnp.where(T_ref > 0, T_ref, 1.0), 0.0)
    q = jnp.clip(jnp.maximum(q, thresholds.support_min_rate), 1e-6, 1.0 - 1e-6)
    plausible = misses_plausible(k_views, T_views, q, thresholds.support_alpha, M)
    return valid & ~behind & plausible, q


def support_keep(*args) -> Bool[Array, " G"]:
    """``(G,)``: the valid groups that pass the visibility-support test (:func:`support_test`,
    the same arguments)."""
    return support_test(*args)[0]


def support_stage(scene: Scene, state: State, options: None) -> State:
    """Drop the groups that views seeing their point do not detect (needs a fit)."""
    fit = state.fit
    keep, miss_rate = support_test(
        scene.rig,
        scene.xy,
        scene.mask,
        fit.X,
        fit.member,
        state.table.valid,
        scene.tau,
        scene.thresholds,
    )
    return state._replace(
        table=state.table.keep(keep),
        fit=fit._replace(member=fit.member & keep[:, None]),
        miss_rate=miss_rate,
    )


SUPPORT = Stage(
    "support",
    support_stage,
    None,
    Switch("support_filter", False, "drop groups that views seeing their point do not detect"),
    thresholds=(
        Threshold("support_frac", 3.0, doc="a detection within support_frac · τ explains a view"),
        Threshold(
            "support_alpha",
            0.01,
            Range(0.0, 1.0),
            "drop if P(that many misses) < support_alpha (a probability)",
        ),
        Threshold("support_min_rate", 0.02, Range(0.0, 1.0), "floor of the estimated miss rate"),
        Threshold(
            "support_ref_views", 4.0, doc="members of the groups that estimate the miss rate"
        ),
    ),
)
