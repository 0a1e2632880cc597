"""Recovery of leftover detections by reprojection (beyond the paper; ``Config.recover``).

Pruning and outlier removal leave correct detections unassigned, most often the third or
fourth view of a point whose group survived. Each leftover detection joins the group
(lacking its view, ≥ 2 members, point in front of the camera) whose triangulated point
reprojects closest to it, if closer than ``recover_frac · τ`` pixels; when detections of
one view compete for a group, the closest wins (ties: smallest node index).
"""

import jax.numpy as jnp

from .._types import Array, Bool, Float, Int
from ..cdog._config import Switch, Threshold, ThresholdsBase
from ..cdog._stage import Scene, Stage, State
from ..geometry._camera import Rig
from ..geometry._projection import distances_to_detections
from ._attach import attach_cheapest, leftover_nodes


def recover_leftovers(
    rig: Rig,
    xy: Float[Array, "M P 2"],
    mask: Bool[Array, "M P"],
    groups: Int[Array, "G M"],
    valid: Bool[Array, " G"],
    X: Float[Array, "G 3"],
    tau_px: Float[Array, ""],
    thresholds: ThresholdsBase,
) -> Int[Array, "G M"]:
    """The group table ``(G, M)`` with leftover detections attached (``xy (M, P, 2)`` pixels,
    ``X (G, 3)`` the groups' points)."""
    G, M = groups.shape
    P = mask.shape[1]
    N = M * P
    member = valid[:, None] & (groups >= 0)
    leftover = leftover_nodes(groups, valid, mask)  # (N,)

    err, in_front = distances_to_detections(rig, X, xy)  # (G, M, P)
    enough = jnp.sum(member, axis=1, dtype=jnp.int32) >= 2
    allowed = (
        (valid & enough)[:, None, None]
        & (~member & in_front)[:, :, None]
        & leftover.reshape(M, P)[None]
    )
    err = jnp.where(allowed, err, jnp.inf).reshape(G, N)

    return attach_cheapest(groups, err, thresholds.recover_frac * tau_px)


def recover_stage(scene: Scene, state: State, options: None) -> State:
    """Attach leftover detections to the groups whose fitted point reprojects near them."""
    groups = recover_leftovers(
        scene.rig, scene.xy, scene.mask, *state.table, state.fit.X, scene.tau, scene.thresholds
    )
    return state._replace(table=state.table._replace(groups=groups), fit=None)


RECOVER = Stage(
    "recover",
    recover_stage,
    None,
    Switch("recover", False, "attach leftovers to groups by reprojection (beyond the paper)"),
    thresholds=(
        Threshold(
            "recover_frac", 1.0, doc="recovery: attach if the reprojection error < recover_frac · τ"
        ),
    ),
)
