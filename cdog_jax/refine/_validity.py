"""The validity gate: the rules every valid group obeys, whatever stage made it
(ALGORITHM.md §12).

A valid group has

1. at least two *counting* views: members whose DLT weight is positive,
2. its point in front of every member camera, ``(R X + t)_z > 0`` (never the sign of the
   homogeneous coordinate: ``K[2,2]`` may be −1),
3. parallax: the largest angle between two members' lines of sight at the point, folded
   into [0°, 90°] (rays that meet at 180° are one line), at least ``min_parallax_deg``,
4. every member's reprojection error at most ``max_err_frac · τ`` pixels.

:func:`validity_gate` first detaches the worst member of each group that breaks rule 4,
one at a time and re-triangulating, while more than two members remain (at most ``M − 2``
rounds); a group that still breaks any rule is dissolved (its members become unassigned).
Rule 5 (:func:`ambiguous_groups`, comment below) then dissolves the groups the epipolar
geometry cannot vouch for: degenerate (the point in one plane with its cameras' centres)
and with a rival detection on the shared epipolar line.
A group that needs no detaching keeps its point as given (weighted, refined), so the gate
changes nothing for groups that already pass. Each rule is a pure function of a batch of
groups, vmappable like the rest of the pipeline.
"""

import jax
import jax.numpy as jnp

from .._status import Status
from .._types import Array, Bool, Float, Int
from ..cdog._config import DEFAULT_MIN_PARALLAX_DEG, Range, Threshold
from ..cdog._stage import GroupTable, Scene, Stage, State, always
from ..geometry._camera import Rig, affine_per_view
from ..geometry._projection import group_errors, reprojection_errors_views_last
from ..geometry._triangulate import dlt_blocks_views_last, solve_normal_3x3
from ..graph._sigma import focal_scale


def counting_views(
    member: Bool[Array, "G M"], *, weights: Float[Array, "G M"] | None = None
) -> Bool[Array, "G M"]:
    """``(G, M)``: the members whose DLT equations count (weight > 0; all members without
    ``weights``)."""
    return member if weights is None else member & (weights > 0)


def in_front_of_members(
    rig: Rig, X: Float[Array, "G 3"], member: Bool[Array, "G M"]
) -> Bool[Array, " G"]:
    """``(G,)``: each point ``X (G, 3)`` lies in front of every member camera,
    ``(R X + t)_z > 0``."""
    depth = affine_per_view(rig.R, rig.t, X)[..., 2]  # (G, M)
    return jnp.all(~member | (depth > 0), axis=1)


def max_parallax_deg(
    rig: Rig, X: Float[Array, "G 3"], member: Bool[Array, "G M"]
) -> Float[Array, " G"]:
    """``(G,)``: the largest angle (degrees, in [0, 90]) between the lines of sight
    ``X − C_m`` of two member views at the point ``X (G, 3)``; 0 with fewer than two members
    or where a camera centre coincides with the point."""
    rays = X[:, None, :] - rig.centers[None, :, :]  # (G, M, 3)
    sq = jnp.sum(rays * rays, axis=-1)
    usable = member & (sq > 0)
    norm = jnp.sqrt(jnp.where(usable, sq, 1.0))
    u = jnp.where(usable[..., None], rays / norm[..., None], 0.0)
    cross = jnp.cross(u[:, :, None, :], u[:, None, :, :])  # (G, M, M, 3)
    sin = jnp.sqrt(jnp.sum(cross * cross, axis=-1) + jnp.finfo(u.dtype).tiny)
    cos = jnp.abs(jnp.einsum("gai,gbi->gab", u, u))
    angle = jnp.degrees(jnp.arctan2(sin, cos))
    pair = usable[:, :, None] & usable[:, None, :]
    return jnp.max(jnp.where(pair, angle, 0.0), axis=(1, 2))


def member_errors(
    rig: Rig, X: Float[Array, "G 3"], xy_g: Float[Array, "G M 2"], member: Bool[Array, "G M"]
) -> Float[Array, "G M"]:
    """``(G, M)``: each member's reprojection distance (px); ``+inf`` where it is not
    finite, ``0`` for non-members."""
    err = reprojection_errors_views_last(rig, X, xy_g)
    err = jnp.where(jnp.isfinite(err), err, jnp.inf)
    return jnp.where(member, err, 0.0)


def errors_within(errors: Float[Array, "G M"], bound_px: Float[Array, ""]) -> Bool[Array, " G"]:
    """``(G,)``: every member error of ``errors (G, M)`` (0 for non-members) is at most
    ``bound_px``."""
    return jnp.all(errors <= bound_px, axis=1)


def detach_worst(
    rig: Rig,
    xy_g: Float[Array, "G M 2"],
    member: Bool[Array, "G M"],
    weights: Float[Array, "G M"],
    X: Float[Array, "G 3"],
    bound_px: Float[Array, ""],
) -> tuple[Bool[Array, "G M"], Float[Array, "G 3"]]:
    """Members ``(G, M)`` and points ``(G, 3)`` after detaching, from every group with more
    than two members whose worst reprojection error exceeds ``bound_px``, its worst member,
    re-triangulating (weighted DLT, ``weights (G, M)``) after each detach; at most ``M − 2``
    rounds. Groups that need no detach keep their point ``X``."""
    M = member.shape[1]
    N, r, origin = dlt_blocks_views_last(rig, xy_g)  # (G, M, 3, 3), (G, M, 3)

    def offenders(member, X):
        err = member_errors(rig, X, xy_g, member)
        n = jnp.sum(member, axis=1, dtype=jnp.int32)
        return err, (n > 2) & ~errors_within(err, bound_px)

    def cond(carry):
        member, X, it = carry
        return (it < M - 2) & jnp.any(offenders(member, X)[1])

    def body(carry):
        member, X, it = carry
        err, bad = offenders(member, X)
        worst = jnp.argmax(err, axis=1).astype(jnp.int32)  # (G,)
        drop = bad[:, None] & (jnp.arange(M, dtype=jnp.int32)[None, :] == worst[:, None])
        member = member & ~drop
        w = jnp.where(member, weights, 0.0)
        X_new, ok = solve_normal_3x3(
            jnp.einsum("gm,gmij->gij", w, N),
            jnp.einsum("gm,gmi->gi", w, r),
            jnp.sum(w > 0, axis=1, dtype=jnp.int32),
        )
        X_new = jnp.where(ok[:, None], X_new + origin[None, :], X)
        return member, jnp.where(bad[:, None], X_new, X), it + 1

    member, X, _ = jax.lax.while_loop(cond, body, (member, X, jnp.int32(0)))
    return member, X


def validity_gate(
    rig: Rig,
    xy_g: Float[Array, "G M 2"],
    member: Bool[Array, "G M"],
    X: Float[Array, "G 3"],
    tau_px: Float[Array, ""],
    max_err_frac: Float[Array, ""],
    min_parallax_deg: Float[Array, ""],
    *,
    weights: Float[Array, "G M"] | None = None,
) -> tuple[Bool[Array, "G M"], Bool[Array, " G"], Float[Array, "G 3"]]:
    """The groups ``member (G, M)`` (members' pixels ``xy_g (G, M, 2)``, points ``X (G, 3)``)
    after the gate of the module docstring: ``(member, valid, X)``, with the members of
    dissolved groups all False. ``weights (G, M)``: the members' DLT weights (default 1)."""
    w = (
        member.astype(X.dtype)
        if weights is None
        else jnp.where(member, weights.astype(X.dtype), 0.0)
    )
    bound = max_err_frac * tau_px
    member, X = detach_worst(rig, xy_g, member, w, X, bound)
    valid = (
        (jnp.sum(counting_views(member, weights=w), axis=1, dtype=jnp.int32) >= 2)
        & in_front_of_members(rig, X, member)
        & (max_parallax_deg(rig, X, member) >= min_parallax_deg)
        & errors_within(member_errors(rig, X, xy_g, member), bound)
    )
    return member & valid[:, None], valid, X


def validity_stage(scene: Scene, state: State, options: None) -> State:
    """The last stage: every valid group passes the gate (needs a fit); the fit holds the
    gated members, points and their errors."""
    fit = state.fit
    member, valid, X = validity_gate(
        scene.rig,
        fit.xy_g,
        fit.member & state.table.valid[:, None],
        fit.X,
        scene.tau,
        scene.thresholds.max_err_frac,
        scene.thresholds.min_parallax_deg,
    )
    ambiguous = valid & ambiguous_groups(
        scene.rig, scene.d, state.table.groups, member, X, scene.tau
    )
    valid = valid & ~ambiguous
    member = member & valid[:, None]
    bpe, err_px = group_errors(scene.rig, X, fit.xy_g, member)
    return state._replace(
        table=GroupTable(state.table.groups, valid),
        fit=fit._replace(member=member, X=X, bpe=bpe, err_px=err_px),
    ).flag(jnp.any(ambiguous), Status.AMBIGUOUS_GEOMETRY)


# The gate every valid group passes (ALGORITHM.md §12). 1° is far below the parallax of
# any benchmark group and well above what float32 can triangulate; 3 τ leaves room above
# recovery's attach gate (recover_frac · τ, 2 τ in extended()).
VALIDITY = Stage(
    "validity_gate",
    validity_stage,
    None,
    always,
    thresholds=(
        Threshold(
            "min_parallax_deg",
            DEFAULT_MIN_PARALLAX_DEG,
            Range(0.0, 90.0, high_open=True),
            "validity gate: the largest angle between members' lines of sight (degrees)",
        ),
        Threshold(
            "max_err_frac",
            3.0,
            Range(0.0, low_open=True),
            "validity gate: every member's reprojection error <= max_err_frac · τ",
        ),
    ),
)


# Rule 5 (applied after the gate, by the validity stage and by every group-table method): a
# group the epipolar geometry cannot vouch for is dissolved. When a group's point lies in one
# plane with the centres of its member cameras, every pairwise epipolar test of its members
# reduces to one line per view (the image of that plane), and with three or more members
# their point is pinned along that line by the reprojection errors alone; two members are
# always in one plane with the point, so a pair is degenerate when every other camera the
# point is in front of lies in that plane too (no view could tell its candidates apart).
# "In one plane" is measured against the gate: the cameras' lines of sight depart from the
# plane by less than τ / f radians (f the rig's focal length), an offset the epipolar test
# cannot see. Degeneracy alone does not make a group wrong (a sparse scene is still
# associated right); it does when the geometry has something to confuse a member with:
# another detection of its view within τ of the epipolar line of every other member.


def off_plane_deg(
    rig: Rig, X: Float[Array, "G 3"], member: Bool[Array, "G M"]
) -> Float[Array, " G"]:
    """``(G,)``: how far (degrees) a group's cameras are from lying in one plane with its
    point ``X (G, 3)``. The cameras measured are the members (three or more), or, for a pair,
    every camera the point is in front of; the plane passes through the point and the two
    measured cameras whose lines of sight are farthest from parallel (the best-conditioned
    plane: noise tilts a plane through nearly parallel lines a lot). The result is the
    largest angle between a measured camera's line of sight and that plane; ``+inf`` where
    fewer than three cameras are measured."""
    rays = rig.centers[None, :, :] - X[:, None, :]  # (G, M, 3)
    sq = jnp.sum(rays * rays, axis=-1)
    usable = sq > 0
    u = rays / jnp.sqrt(jnp.where(usable, sq, 1.0))[..., None]
    member = member & usable
    pair = jnp.sum(member, axis=1) == 2
    front = affine_per_view(rig.R, rig.t, X)[..., 2] > 0  # (G, M)
    measured = member | (pair[:, None] & front & usable)
    normal = jnp.cross(u[:, :, None, :], u[:, None, :, :])  # (G, M, M, 3)
    sin_span = jnp.sqrt(jnp.sum(normal * normal, axis=-1))
    both = measured[:, :, None] & measured[:, None, :]
    G, M = member.shape
    best = jnp.argmax(jnp.where(both, sin_span, -1.0).reshape(G, M * M), axis=1)
    n = jnp.take_along_axis(normal.reshape(G, M * M, 3), best[:, None, None], axis=1)[:, 0]
    n_len = jnp.take_along_axis(sin_span.reshape(G, M * M), best[:, None], axis=1)[:, 0]
    n = n / jnp.where(n_len > 0, n_len, 1.0)[:, None]
    sin_off = jnp.max(jnp.where(measured, jnp.abs(jnp.einsum("gi,gmi->gm", n, u)), 0.0), axis=1)
    enough = (jnp.sum(measured, axis=1) >= 3) & (n_len > 0)
    return jnp.where(enough, jnp.degrees(jnp.arcsin(jnp.clip(sin_off, 0.0, 1.0))), jnp.inf)


# Groups whose rivals are sought at once; the search runs only while degenerate groups are
# left (none in a scene in general position, so it costs nothing there).
RIVAL_BLOCK = 16


def has_rival(
    d: Float[Array, "M P M P"],
    groups: Int[Array, "G M"],
    member: Bool[Array, "G M"],
    tau_px: Float[Array, ""],
    asked: Bool[Array, " G"],
) -> Bool[Array, " G"]:
    """``(G,)``: for the groups ``asked``, some member view holds another detection within
    ``tau_px`` of the epipolar line of every other member: a rival the pairwise epipolar
    tests cannot tell from the member (False for the others). ``d (M, P, M, P)``: the
    scene's epipolar distances (px; ``+inf`` for padding, the same view and, with classes,
    detections of another class); ``groups (G, M)``: slots (−1: none). The asked groups are
    searched :data:`RIVAL_BLOCK` at a time."""
    G, M = groups.shape
    P = d.shape[1]
    block = min(RIVAL_BLOCK, G)
    order = jnp.argsort(~asked, stable=True).astype(jnp.int32)  # the asked groups first
    count = jnp.sum(asked, dtype=jnp.int32)
    views = jnp.arange(M, dtype=jnp.int32)
    slots = jnp.arange(P, dtype=jnp.int32)

    def rivals(rows):
        mem = member[rows]
        slot = jnp.where(mem, groups[rows], 0)  # (B, M)
        # from_member[b, m, n, p] = d[m, slot[b, m], n, p]: member m's line in view n.
        from_member = d[views[None, :], slot]  # (B, M, M, P)
        source = mem[:, :, None] & (views[:, None] != views[None, :])[None]  # (B, m, n)
        fits_all = jnp.all((from_member <= tau_px) | ~source[..., None], axis=1)  # (B, n, P)
        other = slots[None, None, :] != slot[:, :, None]
        pair = jnp.sum(mem, axis=1) >= 2  # a lone member has no line to fit
        return pair & jnp.any(fits_all & other & mem[:, :, None], axis=(1, 2))

    def cond(carry):
        return carry[0] < count

    def body(carry):
        start, found = carry
        start = jnp.minimum(start, G - block)  # the last block may overlap the one before
        rows = jax.lax.dynamic_slice(order, (start,), (block,))
        return start + block, found.at[rows].set(rivals(rows) & asked[rows])

    _, found = jax.lax.while_loop(cond, body, (jnp.int32(0), jnp.zeros((G,), bool)))
    return found


def ambiguous_groups(
    rig: Rig,
    d: Float[Array, "M P M P"],
    groups: Int[Array, "G M"],
    member: Bool[Array, "G M"],
    X: Float[Array, "G 3"],
    tau_px: Float[Array, ""],
) -> Bool[Array, " G"]:
    """``(G,)``: the groups rule 5 dissolves: degenerate (:func:`off_plane_deg` below
    ``asin(τ / f)``, ``f`` the rig's focal length) and with a rival (:func:`has_rival`)."""
    bound_deg = jnp.degrees(jnp.arcsin(jnp.clip(tau_px / focal_scale(rig.K), 0.0, 1.0)))
    degenerate = off_plane_deg(rig, X, member) < bound_deg
    return degenerate & has_rival(d, groups, member, tau_px, degenerate)
