"""Each group's point: the multi-view DLT of its members, from the scene's per-node normal
blocks (ALGORITHM.md §8), with its BPE and mean reprojection error."""

from __future__ import annotations

import jax.numpy as jnp

from ..cdog._stage import Fit, GroupTable, Scene, Stage, State, always
from ..geometry._projection import group_errors
from ..geometry._triangulate import solve_normal_3x3
from ..graph._groups import gather_groups


def fit_groups(scene: Scene, table: GroupTable) -> Fit:
    """Every valid group's members, their pixels, multi-view DLT point, BPE and mean error."""
    N_node, r_node, origin = scene.blocks
    member = table.valid[:, None] & (table.groups >= 0)
    xy_g = gather_groups(table.groups, scene.xy)
    N_g, r_g = gather_groups(table.groups, N_node), gather_groups(table.groups, r_node)
    w = member.astype(N_g.dtype)
    X, ok = solve_normal_3x3(jnp.einsum("gm,gmij->gij", w, N_g), jnp.einsum("gm,gmi->gi", w, r_g))
    X = jnp.where(ok[:, None], X + origin[None, :], 0.0)
    bpe, err_px = group_errors(scene.rig, X, xy_g, member)
    return Fit(member, xy_g, X, bpe, err_px)


def fit_stage(scene: Scene, state: State, options: None) -> State:
    """The state with its table fitted."""
    return state._replace(fit=fit_groups(scene, state.table))


FIT = Stage("fit", fit_stage, None, always)
