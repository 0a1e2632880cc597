"""Bundle adjustment with soft matching: 3D points and annealed soft assignments, alternated.

After Gold & Rangarajan (1996), "A graduated assignment algorithm for graph matching"
(IEEE TPAMI 18(4)), and Gold, Rangarajan et al. (1998), "New algorithms for 2D and 3D point
matching: pose estimation and correspondence" (softassign: Sinkhorn normalisation with slack
entries for outliers, under a temperature lowered round by round), here with the unknown
model being one 3D point per group, as in the C-DOG paper's "BA with soft matching" baseline.
"""

import dataclasses
import math
from typing import ClassVar

import jax
import jax.numpy as jnp

from .._method import GroupTableMethod, register_method
from .._types import Array, Bool, Float, Int
from ..geometry._camera import Rig
from ..geometry._projection import project_views_last
from ..geometry._triangulate import dlt_blocks, solve_normal_3x3, triangulate_views_last
from ..graph._groups import gather_groups, groups_from_labels
from ._voting import VotingOptions, voting_groups


@dataclasses.dataclass(frozen=True)
class SoftBAOptions:
    """Bundle adjustment with soft matching (softassign; Gold & Rangarajan, 1996).

    Start: the groups of triangulation voting (:class:`VotingOptions`, with the same
    ``reprojection_gate``) give ``K ≤ G = M·P // 2`` initial 3D points (multi-view DLT).
    Then, for ``rounds`` rounds at temperature ``T_k = T_0 · (T_end / T_0)^(k / (rounds − 1))``
    (pixels; ``T_0 = initial_temperature · τ``, ``T_end = final_temperature · τ``, with the
    shared σ-matched gate ``τ = max(2·√2·σ, 1 px)``, so that ``T_end ≈ σ`` by default):

    1. every detection ``(m, i)`` and every point ``g`` in front of view m get the affinity
       ``exp(−e² / 2T²)`` of their reprojection distance ``e`` (px);
    2. per view, ``sinkhorn_iterations`` alternating normalisations (log domain) make each
       point's row and each detection's column sum to 1, with a slack column ("no
       detection of this point in this view") and a slack row ("no point for this
       detection"), both of affinity ``exp(−(slack_gate · τ)² / 2T²)``;
    3. each point is re-estimated by DLT with every detection's equations weighted by its
       soft assignment (a point whose weighted system is ill-conditioned keeps its place).

    Harden: each detection goes to the point of its largest assignment if its reprojection
    distance from it is below ``reprojection_gate · τ``; a point keeps at most one detection
    per view (the nearest); points with ≥ 2 detections are the groups. Every loop has a
    static length: the status is always 0.

    Attributes:
        rounds: static ``≥ 1``; annealing rounds.
        sinkhorn_iterations: static ``≥ 1``; normalisations per round.
        reprojection_gate: traced; hardening (and voting) gate, in units of τ.
        initial_temperature: traced; ``T_0`` in units of τ.
        final_temperature: traced; ``T_end`` in units of τ (``1 / (2√2)``: σ when σ sets τ).
        slack_gate: traced; the slack's affinity is that of a detection this many τ away.
    """

    rounds: int = 6
    sinkhorn_iterations: int = 8
    reprojection_gate: float = 2.0
    initial_temperature: float = 1.0
    final_temperature: float = 0.35
    slack_gate: float = 2.0
    THRESHOLDS: ClassVar[tuple[str, ...]] = (
        "reprojection_gate",
        "initial_temperature",
        "final_temperature",
        "slack_gate",
    )

    def __post_init__(self):
        for name in ("rounds", "sinkhorn_iterations"):
            k = getattr(self, name)
            if not isinstance(k, int) or isinstance(k, bool) or k < 1:
                raise ValueError(f"SoftBAOptions.{name} must be an int >= 1; got {k!r}")
        for name in self.THRESHOLDS:
            v = getattr(self, name)
            if (
                isinstance(v, bool)
                or not isinstance(v, (int, float))
                or not math.isfinite(v)
                or v <= 0
            ):
                raise ValueError(f"SoftBAOptions.{name} must be a finite number > 0; got {v!r}")


def _soft_assignment(
    log_affinity: Float[Array, "G M P"], log_slack: Float[Array, ""], iterations: int
) -> Float[Array, "G M P"]:
    """Log soft assignments ``(G, M, P)`` after Sinkhorn normalisation per view: rows
    (points) over their detections and a slack column, columns (detections) over the
    points and a slack row. ``-inf`` entries stay ``-inf``."""
    G, M, P = log_affinity.shape
    slack_col = jnp.full((G, M), log_slack, log_affinity.dtype)
    slack_row = jnp.full((M, P), log_slack, log_affinity.dtype)

    def step(_, carry):
        a, col, row = carry
        rows = jnp.logaddexp(jax.nn.logsumexp(a, axis=2), col)  # (G, M)
        a, col = a - rows[:, :, None], col - rows
        cols = jnp.logaddexp(jax.nn.logsumexp(a, axis=0), row)  # (M, P)
        return a - cols[None], col, row - cols

    a, _, _ = jax.lax.fori_loop(0, iterations, step, (log_affinity, slack_col, slack_row))
    return a


def soft_ba_groups(
    rig: Rig,
    xy: Float[Array, "M P 2"],
    mask: Bool[Array, "M P"],
    d: Float[Array, "M P M P"],
    tau: Float[Array, ""],
    sigma: Float[Array, ""],
    thresholds: dict[str, Float[Array, ""]],
    options: SoftBAOptions,
) -> tuple[Int[Array, "G M"], Bool[Array, " G"], Int[Array, ""]]:
    """Groups ``(G, M)`` (slot per view or -1), ``valid (G,)`` and status ``()`` (always 0)
    of bundle adjustment with soft matching; ``xy (M, P, 2)`` pixels, ``d`` the epipolar
    distances (px), ``tau`` the gate (px), ``thresholds`` the traced numbers of
    :class:`SoftBAOptions`. Valid groups come first, ordered by their smallest node."""
    M, P = mask.shape
    N = M * P
    if M < 2:
        return groups_from_labels(jnp.arange(N, dtype=jnp.int32), jnp.zeros((N,), bool), M, P) + (
            jnp.int32(0),
        )
    xy = jnp.where(mask[..., None], xy, 0.0)
    dtype = xy.dtype
    gate = thresholds["reprojection_gate"] * tau
    seeds, alive, _ = voting_groups(
        rig,
        xy,
        mask,
        d,
        tau,
        sigma,
        {"reprojection_gate": thresholds["reprojection_gate"]},
        VotingOptions(),
    )
    member = alive[:, None] & (seeds >= 0)
    X, ok = triangulate_views_last(rig, gather_groups(seeds, xy), member)
    alive = alive & ok
    N_blocks, r_blocks, origin = dlt_blocks(rig, xy)  # (M, P, 3, 3), (M, P, 3)

    def distances(X):
        xy_hat, front = project_views_last(rig, X)  # (G, M, 2), (G, M)
        dx = xy_hat[:, :, None, 0] - xy[None, :, :, 0]
        dy = xy_hat[:, :, None, 1] - xy[None, :, :, 1]
        usable = alive[:, None, None] & front[:, :, None] & mask[None]
        return jnp.where(
            usable, jnp.sqrt(jnp.where(usable, dx * dx + dy * dy, 0.0)), jnp.inf
        )  # (G, M, P)

    t0 = thresholds["initial_temperature"] * tau
    t_end = thresholds["final_temperature"] * tau
    last = max(options.rounds - 1, 1)

    def anneal(k, X):
        T = t0 * (t_end / t0) ** (jnp.asarray(k, dtype) / last)
        e = distances(X)
        log_aff = jnp.where(
            jnp.isfinite(e), -0.5 * (jnp.where(jnp.isfinite(e), e, 0.0) / T) ** 2, -jnp.inf
        )
        log_slack = -0.5 * (thresholds["slack_gate"] * tau / T) ** 2
        w = jnp.exp(_soft_assignment(log_aff, log_slack, options.sinkhorn_iterations))  # (G, M, P)
        X_new, solved = solve_normal_3x3(
            jnp.einsum("gmp,mpij->gij", w, N_blocks), jnp.einsum("gmp,mpi->gi", w, r_blocks)
        )
        return jnp.where((alive & solved)[:, None], X_new + origin[None, :], X)

    X = jax.lax.fori_loop(0, options.rounds, anneal, X)
    e = distances(X)
    T = t_end
    log_aff = jnp.where(
        jnp.isfinite(e), -0.5 * (jnp.where(jnp.isfinite(e), e, 0.0) / T) ** 2, -jnp.inf
    )
    log_w = _soft_assignment(
        log_aff, -0.5 * (thresholds["slack_gate"] * tau / T) ** 2, options.sinkhorn_iterations
    )
    choice = jnp.argmax(log_w, axis=0).astype(jnp.int32)  # (M, P): first of equals
    chosen_e = jnp.take_along_axis(e, choice[None], axis=0)[0]  # (M, P)
    assigned = mask & (chosen_e < gate)
    points = jnp.arange(e.shape[0], dtype=jnp.int32)
    claim = assigned[None] & (choice[None] == points[:, None, None])  # (G, M, P)
    cost = jnp.where(claim, e, jnp.inf)
    slot = jnp.argmin(cost, axis=2).astype(jnp.int32)  # nearest claimant; ties: smallest slot
    rows = jnp.where(jnp.min(cost, axis=2) < jnp.inf, slot, -1)  # (G, M)
    # Renumber as every method does: groups ordered by their smallest node m * P + i.
    views = jnp.arange(M, dtype=jnp.int32)
    kept = rows >= 0
    node = jnp.where(kept, views[None, :] * P + rows, N)
    root = jnp.min(node, axis=1)
    labels = (
        jnp.arange(N, dtype=jnp.int32).at[node.reshape(-1)].set(jnp.repeat(root, M), mode="drop")
    )
    groups, valid = groups_from_labels(labels, mask.reshape(N), M, P)
    return groups, valid, jnp.int32(0)


@dataclasses.dataclass(frozen=True)
class SoftBA(GroupTableMethod, SoftBAOptions):
    """Bundle adjustment with soft matching as a registered method (``"soft_ba"``): the
    options and algorithm of :class:`SoftBAOptions`, with the σ, gate, triangulation and
    validity gate every group-table method shares (:class:`cdog_jax.GroupTableMethod`).
    """

    def __post_init__(self):
        GroupTableMethod.__post_init__(self)
        SoftBAOptions.__post_init__(self)

    def group_table(self, rig, xy, mask, d, sigma, tau, thresholds):
        by_name = {name: getattr(thresholds, name) for name in self.THRESHOLDS}
        return soft_ba_groups(rig, xy, mask, d, tau, sigma, by_name, self)


register_method("soft_ba", SoftBA)
