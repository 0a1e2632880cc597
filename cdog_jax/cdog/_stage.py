"""What C-DOG's stages share: the scene's tables, the group table, and the stage record
(docs/ARCHITECTURE.md, "How to add a stage").

Every stage has one signature, ``stage(scene, state, options) -> state``: ``scene`` holds the
per-scene tables computed once (detections, epipolar distances, DLT blocks, σ, τ and the
traced thresholds), ``state`` the group table and the latest fit, ``options`` the stage's own
static options (a small ``NamedTuple``). A stage reads its numbers from ``scene.thresholds`` (traced).

A stage declares its options once, in its :class:`Stage` entry: the fields (with defaults)
of its options ``NamedTuple``, its :class:`~cdog_jax.cdog._config.Threshold` entries and its
:class:`~cdog_jax.cdog._config.Switch`; :class:`cdog_jax.Config` and :class:`cdog_jax.Thresholds`
are derived from them (``cdog_jax/cdog/_options.py``).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import NamedTuple

import jax.numpy as jnp

from .._status import Status
from .._types import Array, Bool, Float, Int
from ..geometry._camera import Rig
from ._config import Threshold, ThresholdsBase


class Scene(NamedTuple):
    """One scene's tables, computed once and read by every stage.

    ``xy (M, P, 2)`` pixels (padding zeroed), ``mask (M, P)``, ``node_valid (N,)`` the nodes a
    graph stage may use (``mask`` flattened; fewer when regrouping leftovers), ``d (M, P, M, P)``
    epipolar distances (px), ``blocks`` the per-node DLT normal blocks ``(M, P, 3, 3)``,
    ``(M, P, 3)`` and their origin ``(3,)``, ``sigma`` and ``tau`` (px), ``thresholds`` the thresholds.
    """

    rig: Rig
    xy: Float[Array, "M P 2"]
    mask: Bool[Array, "M P"]
    node_valid: Bool[Array, " N"]
    d: Float[Array, "M P M P"]
    blocks: tuple
    sigma: Float[Array, ""]
    tau: Float[Array, ""]
    thresholds: ThresholdsBase


class GroupTable(NamedTuple):
    """``groups (G, M)`` slot per view or -1, and ``valid (G,)``; a group that is not valid
    has a row of -1 (stages that drop groups clear their rows)."""

    groups: Int[Array, "G M"]
    valid: Bool[Array, " G"]

    def keep(self, valid: Bool[Array, " G"]) -> GroupTable:
        """Only the groups of ``valid`` (a subset of ``self.valid``), their rows cleared."""
        return GroupTable(jnp.where(valid[:, None], self.groups, -1), valid)


class Fit(NamedTuple):
    """Each group's members ``(G, M)``, their pixels ``(G, M, 2)``, the multi-view DLT point
    ``X (G, 3)`` (scene units), its BPE ``(G,)`` (px²) and mean error ``(G,)`` (px)."""

    member: Bool[Array, "G M"]
    xy_g: Float[Array, "G M 2"]
    X: Float[Array, "G 3"]
    bpe: Float[Array, " G"]
    err_px: Float[Array, " G"]


class State(NamedTuple):
    """The group table, the fit of the table as it was last fitted (``None`` before the
    first fit), the int32 :class:`~cdog_jax.Status` bits raised so far, and the scene's miss
    rate as the support filter estimated it (``()``, the share of views that see a trusted
    group's point without detecting it; ``None`` before the filter runs)."""

    table: GroupTable
    fit: Fit | None
    status: Int[Array, ""]
    miss_rate: Float[Array, ""] | None = None

    def flag(self, condition: Bool[Array, ""], flag: Status) -> State:
        """This state with ``flag`` raised where ``condition`` holds."""
        return self._replace(status=self.status | raise_flag(condition, flag))


def raise_flag(condition: Bool[Array, ""], flag: Status) -> Int[Array, ""]:
    """``()`` int32: ``flag`` where ``condition`` holds, else 0."""
    return jnp.where(condition, jnp.int32(int(flag)), jnp.int32(0))


class Stage(NamedTuple):
    """One entry of C-DOG's stage list, and the declaration of the stage's options.

    ``name``; ``run(scene, state, options) -> state``; ``options``: the ``NamedTuple`` class
    of its structural options, each field with its default (``Literal[...]``, ``bool`` or a
    positive ``int``; each field becomes a field of :class:`cdog_jax.Config`; ``None``: no
    options); ``when``: a predicate of the config, or a :class:`~cdog_jax.cdog._config.Switch`
    (a ``bool`` field of the config); ``numbers``: its traced numbers (fields of the config
    and of :class:`cdog_jax.Thresholds`); ``options_from``: for options made from the config
    rather than read from it by name (regrouping's resolved stages), ``config -> options``.
    """

    name: str
    run: Callable
    options: type | None
    when: Callable[[object], bool]
    thresholds: tuple[Threshold, ...] = ()
    options_from: Callable[[object], object] | None = None


def always(config) -> bool:
    """The predicate of a stage that always runs."""
    return True
