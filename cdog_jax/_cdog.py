"""C-DOG, the method (docs/ALGORITHM.md): its options and presets (:class:`Config`), its
stages in order (:data:`STAGES`), and :func:`associate_traced`, the pure function of one
scene that runs them.

Every stage has one signature, ``stage(scene, state, options) -> state``
(``cdog_jax/_stage.py``), lives in the file of its rule (``graph/``, ``refine/``) with its
own options, and appears once below; a preset is a :class:`Config`, whose switches decide
which stages run.
"""

from __future__ import annotations

import dataclasses
from typing import NamedTuple

import jax.numpy as jnp
import numpy as np
import jax

from ._config import (
    _NUMERIC,
    DEFAULT_MIN_PARALLAX_DEG,
    Adjacency,
    IqrQuartiles,
    IqrScore,
    PruneScope,
    SigmaMode,
    Thresholds,
    check_number,
    check_thresholds,
    tau_px,
)
from ._expect import expect_args
from ._method import Method, Observations, register_method
from ._result import Association, association_from_groups
from ._stage import GroupTable, Scene, Stage, State, raise_flag
from ._status import Status
from ._types import Array, Bool, Float
from .geometry._camera import Rig
from .geometry._epipolar import epipolar_distances
from .geometry._triangulate import dlt_blocks
from .graph._graph_stage import GRAPH
from .graph._groups import compact_groups
from .graph._sigma import estimate_sigma, focal_scale
from .refine._attach import leftover_nodes
from .refine._bpe_filter import BPE_FILTER
from .refine._fit import FIT
from .refine._least_squares import REFINE
from .refine._outliers import IQR
from .refine._reassign import REASSIGN
from .refine._recovery import RECOVER
from .refine._second_association import SECOND_ASSOCIATION
from .refine._seed import SEED
from .refine._support import SUPPORT
from .refine._validity import VALIDITY


@dataclasses.dataclass(frozen=True)
class Config(Method):
    """C-DOG, the method: its options and presets. Structural fields change the compiled
    program; numeric ones do not (they become :class:`Thresholds`).

    The stages that run and the options each one reads are listed once, in order, in
    ``cdog_jax/_cdog.py`` (docs/ARCHITECTURE.md); the fields below are grouped by stage.

    Presets: :meth:`paper` (the paper's method, our defaults), :meth:`extended` (beyond the
    paper), :meth:`best` (the most accurate; the default method of ``associate``) and
    :meth:`reference` (the original public implementation's behaviour, docs/BENCHMARK.md §5).
    """

    # --- structure (part of the jit key) ---
    adjacency: Adjacency = "mutual"
    prune_scope: PruneScope = "all"
    iqr: bool = True
    iqr_score: IqrScore = "exclude_own"
    iqr_quartiles: IqrQuartiles = "zero_pad"
    iqr_guards: bool = False  # reference's 10 px / 50 px rules
    second_association: bool = False
    recover: bool = False  # attach leftovers to groups by reprojection (beyond the paper)
    regroup: bool = False  # run Alg. 1-3 again on what is left (beyond the paper)
    support_filter: bool = False  # drop groups that views seeing their point do not detect
    seed: bool = False  # groups from two-view hypotheses on what is still left (beyond the paper)
    reassign: bool = False  # each detection to its nearest point, refitting (beyond the paper)
    bpe_filter: bool = True
    refine: bool = False
    sigma_mode: SigmaMode = "given"
    max_split_iters: int = 64
    max_iqr_iters: int = 16
    refine_max_steps: int = 20
    jump_min_gaps: int = 3  # gaps needed before a jump can be declared
    seed_min_views: int = 2  # members (pair + voters) a seeded group needs
    reassign_iters: int = 3  # rounds of re-assignment and refitting
    # --- numeric defaults (become a traced Thresholds) ---
    alpha_tau: float = 2.0
    tau_min_px: float = 1.0
    delta: float = 0.5
    iqr_alpha: float = 2.0
    iqr_floor_px: float = 1.0
    iqr_min_px: float = 10.0
    iqr_force_px: float = 50.0
    jump_kappa: float = 10.0
    jump_floor_px2: float = 4.0
    jump_floor_sigma: float = 3.0
    second_frac: float = 0.5
    recover_frac: float = 1.0
    support_frac: float = 3.0
    support_alpha: float = 0.01
    support_min_rate: float = 0.02
    support_ref_views: float = 4.0
    # The validity gate every valid group passes (ALGORITHM.md §12). 1° is far below the
    # parallax of any benchmark group and well above what float32 can triangulate; 3 τ
    # leaves room above recovery's attach gate (recover_frac · τ, 2 τ in extended()).
    min_parallax_deg: float = DEFAULT_MIN_PARALLAX_DEG
    max_err_frac: float = 3.0
    seed_frac: float = 1.5
    reassign_frac: float = 2.0

    def __post_init__(self):
        choices = {
            "adjacency": ("mutual", "union"),
            "prune_scope": ("all", "conflicts", "none"),
            "iqr_score": ("exclude_own", "include_own"),
            "iqr_quartiles": ("zero_pad", "positive"),
            "sigma_mode": ("given", "auto"),
        }
        for name, allowed in choices.items():
            if getattr(self, name) not in allowed:
                raise ValueError(f"Config.{name} must be one of {allowed}; got {getattr(self, name)!r}")
        for name in ("max_split_iters", "max_iqr_iters", "refine_max_steps", "jump_min_gaps", "reassign_iters"):
            value = getattr(self, name)
            if not isinstance(value, int) or isinstance(value, bool) or value < 1:
                raise ValueError(f"Config.{name} must be a positive int; got {value!r}")
        if not isinstance(self.seed_min_views, int) or isinstance(self.seed_min_views, bool) or self.seed_min_views < 2:
            raise ValueError(f"Config.seed_min_views must be an int >= 2; got {self.seed_min_views!r}")
        for field in dataclasses.fields(self):
            if field.type == "bool" and not isinstance(getattr(self, field.name), bool):
                raise TypeError(f"Config.{field.name} must be True or False; got {getattr(self, field.name)!r}")
        for name in _NUMERIC:
            check_number(getattr(self, name), name, "Config")

    @classmethod
    def paper(cls, **overrides) -> "Config":
        """The paper's C-DOG (Alg. 1–3 and §IV-E) with noise-matched τ."""
        return cls(**overrides)

    @classmethod
    def extended(cls, **overrides) -> "Config":
        """Beyond the paper: union adjacency, then leftover detections are attached to groups
        by reprojection (``recover``) and what is still left is associated again
        (``regroup``). Recovers most points the paper's pruning loses (2-view points above all)."""
        base = dict(adjacency="union", recover=True, recover_frac=2.0, regroup=True)
        base.update(overrides)
        return cls(**base)

    @classmethod
    def best(cls, **overrides) -> "Config":
        """Our most accurate C-DOG, the default: :meth:`extended`, then groups seeded from
        two-view hypotheses on what is still left (``seed``), rounds of nearest-point
        re-assignment with merging of split groups (``reassign``), and seeding once more on
        what those rounds detached. Leaves few detections unassigned at large σ, where
        pruning and the IQR leave most of a dense scene over (docs/ALGORITHM.md §8e–8f)."""
        base = dict(adjacency="union", recover=True, recover_frac=2.0, regroup=True, seed=True, reassign=True)
        base.update(overrides)
        return cls(**base)

    @classmethod
    def reference(cls, **overrides) -> "Config":
        """The original public code's choices (docs/BENCHMARK.md §5): fixed τ = 10 px, δ-pruning only of
        view-conflicting components, IQR α = 1.5 on positive scores with own errors and the
        10/50 px guards, no BPE filter, then the second association."""
        base = dict(
            adjacency="mutual",
            prune_scope="conflicts",
            iqr_alpha=1.5,
            iqr_floor_px=0.0,
            iqr_score="include_own",
            iqr_quartiles="positive",
            iqr_guards=True,
            bpe_filter=False,
            second_association=True,
            alpha_tau=0.0,
            tau_min_px=10.0,
        )
        base.update(overrides)
        return cls(**base)

    def replace(self, **changes) -> "Config":
        """A copy with ``changes`` applied; checked like a new Config."""
        return dataclasses.replace(self, **changes)

    def thresholds(self, sigma_px=0.0, *, dtype=None) -> Thresholds:
        """The numeric fields (and σ) as a :class:`Thresholds` of scalar arrays.

        NumPy scalars (cheap to pass to a jitted function), except that a JAX ``sigma_px``
        (traced, or batched) stays a JAX array.
        """
        dtype = np.dtype(jax.dtypes.canonicalize_dtype(dtype or jnp.float32))
        values = {name: np.asarray(getattr(self, name), dtype) for name in _NUMERIC}
        sigma = jnp.asarray(sigma_px, dtype) if isinstance(sigma_px, jax.Array) else np.asarray(sigma_px, dtype)
        return Thresholds(sigma_px=sigma, **values)

    def structure(self) -> "Config":
        """This config with its numeric fields reset to the defaults: the part a jit key needs."""
        defaults = Config()
        return dataclasses.replace(self, **{name: getattr(defaults, name) for name in _NUMERIC})

    def check_thresholds(self, thresholds: Thresholds) -> None:
        """Raise for a concrete threshold outside its range (:data:`RANGES`)."""
        check_thresholds(thresholds)

    def associate_scene(self, rig, observations: Observations, thresholds: Thresholds):
        """C-DOG on one scene (:func:`cdog_jax.associate_traced`); ``observations.weights``
        are applied by the callers when the final points are triangulated."""
        return associate_traced(rig, observations.xy, observations.mask, thresholds, self)

    def table_bytes(self, num_views: int, itemsize: int) -> float:
        """Bytes per ``N²`` at the peak of one scene, by the stages that run (the coefficients
        were checked against XLA's ``memory_analysis()``, ALGORITHM.md §14)."""
        f = float(itemsize)
        # d and its masked copy, the proposal/adjacency bool tables, and (above N ≈ 10⁴, where
        # XLA stops reusing some of them) about 2 more bytes per pair.
        stages = [2.0 * f + 5.0]
        if self.second_association:
            stages.append(f * (num_views / 2.0 + 1.0))  # (G, M, N) distances beside d
        if self.recover or self.regroup:
            stages.append(3.0 * f + 6.0)  # d kept for regrouping, (G, N, 2) differences
        if self.seed:
            # (H, M, P) hypothesis tables with H = N·M, M·N² entries each: the distances, the
            # votes and about half a table of differences that XLA does not fuse, beside d
            # and the symmetric cost (checked against memory_analysis() at M = 4 and 8).
            stages.append(num_views * (1.5 * f + 1.0) + 3.0 * f)
        coeff = max(stages)
        if self.support_filter and (self.recover or self.regroup):
            coeff += f  # (G, M, P, 2) differences while the regrouped tables are alive
        if self.refine:
            coeff += 0.5 * f
        return coeff


# --------------------------------------------------------------------------- the stages


ASSOCIATION = (GRAPH, IQR)
"""Alg. 1–3: the stages that make groups from nodes; :data:`REGROUP` runs them again on
the detections the first pass left over."""


class RegroupOptions(NamedTuple):
    """The regroup stage's option: the resolved :data:`ASSOCIATION` stages it runs again."""

    plan: tuple


def _merge_groups(a: GroupTable, b: GroupTable) -> GroupTable:
    """Two tables of disjoint groups as one of the same capacity (at most N/2 groups exist)."""
    G = a.groups.shape[0]
    groups = jnp.concatenate([a.groups, b.groups])
    valid = jnp.concatenate([a.valid, b.valid])
    groups, valid, _ = compact_groups(jnp.where(valid[:, None], groups, -1), valid)
    return GroupTable(groups[:G], valid[:G])


def regroup_stage(scene: Scene, state: State, options: RegroupOptions) -> State:
    """Alg. 1–3 again on the detections in no valid group; the new groups join the table."""
    left = leftover_nodes(*state.table, scene.mask)
    again = run_plan(options.plan, scene._replace(node_valid=left), state._replace(status=jnp.int32(0)))
    return State(_merge_groups(state.table, again.table), None, state.status | again.status)


REGROUP = Stage("regroup", regroup_stage, RegroupOptions, lambda config: config.regroup)
_REFIT_WHEN = lambda config: config.recover or config.regroup or config.seed or config.reassign  # noqa: E731

STAGES: tuple[Stage, ...] = (
    *ASSOCIATION,
    SECOND_ASSOCIATION,
    FIT,
    BPE_FILTER,
    SUPPORT,
    RECOVER,
    REGROUP,
    SEED,
    REASSIGN,
    SEED._replace(name="seed_again", when=lambda config: config.seed and config.reassign),
    FIT._replace(name="refit", when=_REFIT_WHEN),
    SUPPORT._replace(name="support_again", when=lambda config: config.support_filter and _REFIT_WHEN(config)),
    REFINE,
    VALIDITY,
)
"""C-DOG in order. A stage runs when its ``when(config)`` holds; a step that repeats (the
fit and the support filter after recovery and regrouping) is the same stage listed again."""


def stage_options(stage: Stage, config: "Config"):
    """The stage's own options, read from ``config`` (``None`` for a stage without any)."""
    if stage.options is None:
        return None
    if stage.options is RegroupOptions:
        return RegroupOptions(plan(config, ASSOCIATION))
    return stage.options(**{name: getattr(config, name) for name in stage.options._fields})


def plan(config: "Config", stages: tuple[Stage, ...] = STAGES) -> tuple[tuple[Stage, object], ...]:
    """The stages of ``stages`` that run under ``config``, each with its options (static)."""
    return tuple((stage, stage_options(stage, config)) for stage in stages if stage.when(config))


def run_plan(steps, scene: Scene, state: State) -> State:
    """Run the resolved stages in order."""
    for stage, options in steps:
        state = stage.run(scene, state, options)
    return state


def associate_traced(
    rig: Rig,
    xy: Float[Array, "M P 2"],
    mask: Bool[Array, "M P"],
    thresholds: Thresholds,
    config: Config,
) -> Association:
    """C-DOG on one scene as a pure function; no input checks.

    Args:
        rig: cameras, ``K, R, t`` of shapes ``(M, 3, 3), (M, 3, 3), (M, 3)``.
        xy: ``(M, P, 2)`` detections in pixels; padded slots may hold anything.
        mask: ``(M, P)`` bool, slot holds a detection.
        thresholds: numeric thresholds and σ (traced; see ``Config.thresholds``).
        config: structural configuration (static under ``jit``).
    """
    expect_args("associate_traced", rig=(rig, Rig), thresholds=(thresholds, Thresholds), config=(config, Config))
    th = Thresholds(*(jnp.asarray(v) for v in thresholds))  # NumPy scalars when called eagerly
    M, P = mask.shape
    xy = jnp.where(mask[..., None], xy, 0.0)  # padding is neutral from here on
    d = epipolar_distances(rig, xy, mask)  # (M, P, M, P)
    if config.sigma_mode == "auto":
        sigma, fallback = estimate_sigma(d, mask, focal_scale(rig.K))
    else:
        sigma, fallback = th.sigma_px, jnp.asarray(False)
    tau = tau_px(th, sigma)
    scene = Scene(rig, xy, mask, mask.reshape(-1), d, dlt_blocks(rig, xy), sigma, tau, th)
    G = max(M * P // 2, 1)
    empty = GroupTable(jnp.full((G, M), -1, jnp.int32), jnp.zeros((G,), bool))
    state = run_plan(plan(config), scene, State(empty, None, raise_flag(fallback, Status.SIGMA_FALLBACK)))
    fit = state.fit
    return association_from_groups(
        state.table.groups, state.table.valid, fit.member, fit.X, fit.bpe, fit.err_px, P,
        jnp.asarray(sigma, xy.dtype), jnp.asarray(tau, xy.dtype), state.status,
    )


register_method("best", Config.best)
register_method("extended", Config.extended)
register_method("paper", Config.paper)
register_method("reference", Config.reference)
