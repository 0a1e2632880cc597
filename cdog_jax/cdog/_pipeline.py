"""C-DOG, the method (docs/ALGORITHM.md): its stages in order (:data:`STAGES`), its
options and presets (:class:`Config`), and :func:`associate_traced`, the pure function of
one scene that runs them.

Every stage has one signature, ``stage(scene, state, options) -> state``
(``cdog_jax/cdog/_stage.py``), lives in the file of its rule (``graph/``, ``refine/``) with the
declaration of its own options, and appears once below. :class:`Config`'s fields, their
defaults and checks, the traced :class:`Thresholds` and :data:`RANGES` are derived from
those declarations (``cdog_jax/cdog/_options.py``); a preset is a :class:`Config`, whose switches
decide which stages run.
"""

from __future__ import annotations

import dataclasses
import sys
import typing
from typing import ClassVar, NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from .._expect import expect_args
from .._method import Method, Observations, finite_observations, register_method
from .._result import Association, association_from_groups
from .._runtime.xla_kernels import COMPILER_OPTIONS
from .._status import Status
from .._types import Array, Bool, Float, Int
from ..geometry._camera import Rig
from ..geometry._epipolar import epipolar_distances
from ..geometry._triangulate import dlt_blocks
from ..graph._graph_stage import GRAPH
from ..graph._groups import compact_groups
from ..graph._sigma import estimate_sigma, focal_scale
from ..graph._sigma_robust import estimate_noise
from ..refine._ambiguity import AMBIGUITY
from ..refine._attach import leftover_nodes
from ..refine._bpe_filter import BPE_FILTER
from ..refine._fit import FIT, fit_groups
from ..refine._least_squares import REFINE
from ..refine._outliers import IQR
from ..refine._reassign import REASSIGN
from ..refine._recovery import RECOVER
from ..refine._second_association import SECOND_ASSOCIATION
from ..refine._seed import SEED
from ..refine._support import SUPPORT
from ..refine._validity import VALIDITY
from ._config import (
    Adjacency,
    IqrQuartiles,
    IqrScore,
    OptionGroup,
    PruneScope,
    SigmaMode,
    Switch,
    TauMode,
    Threshold,
    ThresholdsBase,
    ThresholdUnit,
    gauss_coverage,
    tau_px,
    thresholds_in_pixels,
)
from ._options import (
    NUMERIC,
    check_thresholds,
    declared_options,
    describe,
    make_thresholds_type,
    ranges,
    units,
)
from ._stage import GroupTable, Scene, Stage, State, raise_flag

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
    again = run_plan(
        options.plan, scene._replace(node_valid=left), state._replace(status=jnp.int32(0))
    )
    return state._replace(
        table=_merge_groups(state.table, again.table), fit=None, status=state.status | again.status
    )


REGROUP = Stage(
    "regroup",
    regroup_stage,
    RegroupOptions,
    Switch("regroup", False, "run Alg. 1–3 again on what is left (beyond the paper)"),
    options_from=lambda config: RegroupOptions(plan(config, ASSOCIATION)),
)
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
    SUPPORT._replace(
        name="support_again", when=lambda config: config.support_filter and _REFIT_WHEN(config)
    ),
    AMBIGUITY,
    REFINE,
    VALIDITY,
)
"""C-DOG in order. A stage runs when its ``when(config)`` holds; a step that repeats (the
fit and the support filter after recovery and regrouping) is the same stage listed again."""


class SceneOptions(NamedTuple):
    """Where σ comes from, the gate τ and the unit of lengths. ``sigma_mode``: σ given by the
    caller, or estimated from the scene's epipolar distances (``"auto"``: the half-normal
    fit; ``"robust"``: half-t fits too, σ from the median true-pair distance; ALGORITHM.md
    §0.1). ``tau_mode``: ``"gaussian"``, τ from σ and the numbers below; ``"fitted"``, τ is
    the ``erf(alpha_tau/√2)``-quantile of the fitted true-pair distance (with
    ``sigma_mode="robust"`` only; else the Gaussian τ). ``threshold_unit``: ``"px"``;
    ``"focal"``, every length (σ given, ``tau_min_px``, the numbers of unit px) is in pixels
    of a camera of focal length 1000 px (ALGORITHM.md §0)."""

    sigma_mode: SigmaMode = "given"
    tau_mode: TauMode = "gaussian"
    threshold_unit: ThresholdUnit = "px"


SCENE = OptionGroup(
    "scene",
    SceneOptions,
    thresholds=(
        Threshold("alpha_tau", 2.0, doc="gate τ = max(alpha_tau · √2 · σ, tau_min_px)"),
        Threshold("tau_min_px", 1.0, doc="the gate's lower bound (pixels)", unit="px"),
    ),
)
"""The options :func:`associate_traced` reads itself, before the stages."""


def stage_options(stage: Stage, config: Config):
    """The stage's own options, read from ``config`` by name (``None`` for a stage without
    any; made by ``stage.options_from`` when it has one)."""
    if stage.options_from is not None:
        return stage.options_from(config)
    if stage.options is None:
        return None
    return stage.options(**{name: getattr(config, name) for name in stage.options._fields})


_DERIVED: dict = {}
"""``(id(config), what, changes) → (config, copy)``: the copies :meth:`Config.replace` and
:meth:`Config.structure` made, so that a loop that derives the same copy of the same config
every call (a live frame: the σ made given, the jit key) checks and builds it once (a
fraction of a millisecond each). Keyed by the config's identity (kept alive beside its copy): equal configs of
other field types (``1`` and ``1.0``) never share a copy."""
_DERIVED_MOST = 256


def _derived(config, what: str, changes: dict):
    """``dataclasses.replace(config, **changes)``, made once per config object and changes."""
    try:
        key = (id(config), what, tuple((k, type(v), v) for k, v in sorted(changes.items())))
        hit = _DERIVED.get(key)
    except TypeError:  # a value that cannot be hashed: made anew
        return dataclasses.replace(config, **changes)
    if hit is not None and hit[0] is config:
        return hit[1]
    copy = dataclasses.replace(config, **changes)
    if len(_DERIVED) >= _DERIVED_MOST:
        _DERIVED.clear()
    _DERIVED[key] = (config, copy)
    return copy


def plan(
    config: Config, stages: tuple[Stage, ...] | None = None
) -> tuple[tuple[Stage, object], ...]:
    """The stages of ``stages`` (default: the config's own, :data:`STAGES`) that run under
    ``config``, each with its options (static)."""
    stages = type(config).stages if stages is None else stages
    return tuple((stage, stage_options(stage, config)) for stage in stages if stage.when(config))


def run_plan(steps, scene: Scene, state: State) -> State:
    """Run the resolved stages in order.

    When a stage runs more than once before the last fit (regrouping runs the graph and the
    IQR again, ``seed_again`` the seeding, ...), the stages up to the last fit run as
    :func:`run_plan_shared`: each distinct stage is then compiled once instead of once per
    occurrence. The last fit and the stages after it are inlined."""
    head, tail = _split_at_last_fit(steps)
    if _has_repeats(head):
        # The last fit and what follows stay inlined: XLA contracts a multiply and an add
        # into one rounding only within a fused loop, so the numbers a step returns depend on
        # what it is compiled beside; the points the result reports keep those of the
        # stages compiled one after another.
        state = run_plan_shared(head, scene, state)
        return run_plan_inline(tail, scene, state)
    return run_plan_inline(steps, scene, state)


def run_plan_inline(steps, scene: Scene, state: State) -> State:
    """Run the resolved stages in order, each one inlined where it occurs."""
    for stage, options in steps:
        state = stage.run(scene, state, options)
    return state


class _Machine(NamedTuple):
    """What :func:`run_plan_shared` carries from step to step: the state (its fit always
    present: the last one made, read only by the stages that read a fit after a fit stage,
    as in the plan), the nodes the graph stages may use, and what regrouping set aside
    (the table and the status before it)."""

    state: State
    node_valid: Bool[Array, " N"]
    aside: tuple


class _StageStep(NamedTuple):
    """One stage with its options as a step of :func:`run_plan_shared` (equal steps are
    compiled once)."""

    run: object
    options: object

    def __call__(self, scene: Scene, machine: _Machine) -> _Machine:
        out = self.run(scene._replace(node_valid=machine.node_valid), machine.state, self.options)
        kept = machine.state
        return machine._replace(
            state=out._replace(
                fit=kept.fit if out.fit is None else out.fit,
                miss_rate=kept.miss_rate if out.miss_rate is None else out.miss_rate,
            )
        )


def _set_aside(scene: Scene, machine: _Machine) -> _Machine:
    """Regrouping begins: the table and status aside, the graph stages see the leftovers."""
    state = machine.state
    left = leftover_nodes(*state.table, scene.mask)
    return _Machine(state._replace(status=jnp.int32(0)), left, (state.table, state.status))


def _merge_aside(scene: Scene, machine: _Machine) -> _Machine:
    """Regrouping ends: the new groups join the table set aside (:func:`regroup_stage`)."""
    table, status = machine.aside
    state = machine.state
    merged = state._replace(table=_merge_groups(table, state.table), status=status | state.status)
    return _Machine(merged, scene.mask.reshape(-1), machine.aside)


def _flat_steps(steps) -> list:
    """The plan as steps of :func:`run_plan_shared`, regrouping unfolded into its stages."""
    flat = []
    for stage, options in steps:
        if stage.run is regroup_stage:
            inner = _flat_steps(options.plan)
            if _set_aside in inner:
                raise ValueError(
                    f"stage {stage.name!r}: regrouping inside regrouping is not supported"
                )
            flat += [_set_aside, *inner, _merge_aside]
        else:
            flat.append(_StageStep(stage.run, options))
    return flat


def _split_at_last_fit(steps) -> tuple[tuple, tuple]:
    """The plan before its last fit stage, and from it on."""
    last_fit = max(
        (i for i, (stage, _) in enumerate(steps) if stage.run is FIT.run), default=len(steps)
    )
    return tuple(steps[:last_fit]), tuple(steps[last_fit:])


def _has_repeats(steps) -> bool:
    flat = [step for step in _flat_steps(steps) if isinstance(step, _StageStep)]
    return len(set(flat)) < len(flat)


def run_plan_shared(steps, scene: Scene, state: State) -> State:
    """Run the resolved stages in order, each distinct stage compiled once: a loop over the
    steps whose body switches on the step (an unbatched index, so under ``vmap`` the switch
    stays a switch and runs one stage per step)."""
    flat = _flat_steps(steps)
    distinct = list(dict.fromkeys(flat))
    which = np.asarray([distinct.index(step) for step in flat], np.int32)
    fit = state.fit
    if fit is None:  # a fit of the right shapes, never read before a fit stage replaces it
        fit = jax.tree.map(
            lambda a: jnp.zeros(a.shape, a.dtype), jax.eval_shape(fit_groups, scene, state.table)
        )
    # The miss rate likewise: NaN until the support filter estimates it (seeding then keeps
    # its rule without one).
    miss_rate = state.miss_rate
    if miss_rate is None:
        miss_rate = jnp.asarray(jnp.nan, scene.xy.dtype)
    machine = _Machine(
        state._replace(fit=fit, miss_rate=miss_rate),
        scene.node_valid,
        (state.table, state.status),
    )
    branches = [lambda m, step=step: step(scene, m) for step in distinct]
    machine = jax.lax.fori_loop(
        0, len(flat), lambda k, m: jax.lax.switch(jnp.asarray(which)[k], branches, m), machine
    )
    return machine.state


def associate_traced(
    rig: Rig,
    xy: Float[Array, "M P 2"],
    mask: Bool[Array, "M P"],
    thresholds: ThresholdsBase,
    config: Config,
    *,
    classes: Int[Array, "M P"] | None = None,
) -> Association:
    """C-DOG on one scene as a pure function; no input checks.

    Args:
        rig: cameras, ``K, R, t`` of shapes ``(M, 3, 3), (M, 3, 3), (M, 3)``.
        xy: ``(M, P, 2)`` detections in pixels; padded slots may hold anything.
        mask: ``(M, P)`` bool, slot holds a detection.
        thresholds: numeric thresholds and σ (traced; see ``Config.thresholds``), of the
            config's type (:class:`Thresholds` for :class:`Config`).
        config: structural configuration (static under ``jit``).
        classes: optional ``(M, P)`` int class of each detection (a keypoint type): two
            detections of different classes get an infinite epipolar distance, so the graph
            never joins them, nor does any stage that reads the distances (σ estimation,
            the split, regrouping, the second association). Recovery and the support filter
            do not read them. ``None``: one class.
    """
    kind = type(config).thresholds_type if isinstance(config, Config) else Thresholds
    expect_args(
        "associate_traced", rig=(rig, Rig), thresholds=(thresholds, kind), config=(config, Config)
    )
    xy, mask, dropped = finite_observations(xy, mask)
    scene, fallback = scene_tables(rig, xy, mask, thresholds, config, classes=classes)
    M, P = mask.shape
    G = max(M * P // 2, 1)
    empty = GroupTable(jnp.full((G, M), -1, jnp.int32), jnp.zeros((G,), bool))
    status = raise_flag(fallback, Status.SIGMA_FALLBACK) | raise_flag(
        dropped, Status.NONFINITE_DETECTION
    )
    state = run_plan(plan(config), scene, State(empty, None, status))
    fit = state.fit
    return association_from_groups(
        state.table.groups,
        state.table.valid,
        fit.member,
        fit.X,
        fit.bpe,
        fit.err_px,
        P,
        jnp.asarray(scene.sigma, xy.dtype),
        jnp.asarray(scene.tau, xy.dtype),
        state.status,
    )


def scene_tables(
    rig: Rig,
    xy: Float[Array, "M P 2"],
    mask: Bool[Array, "M P"],
    thresholds: ThresholdsBase,
    config: Config,
    *,
    classes: Int[Array, "M P"] | None = None,
) -> tuple[Scene, Bool[Array, ""]]:
    """The tables every stage reads (:class:`Scene`: padding zeroed, epipolar distances,
    DLT blocks, σ and τ), and whether σ estimation fell back; arguments as
    :func:`associate_traced`."""
    kind = type(config).thresholds_type
    thresholds = kind(*(jnp.asarray(v) for v in thresholds))  # NumPy scalars when called eagerly
    if config.threshold_unit == "focal":
        thresholds = thresholds_in_pixels(thresholds, focal_scale(rig.K), type(config).units)
    xy = jnp.where(mask[..., None], xy, 0.0)  # padding is neutral from here on
    d = epipolar_distances(rig, xy, mask)  # (M, P, M, P)
    if classes is not None:
        d = jnp.where(classes[:, :, None, None] == classes[None, None, :, :], d, jnp.inf)
    fitted = None
    if config.sigma_mode == "auto":
        sigma, fallback = estimate_sigma(d, mask, focal_scale(rig.K))
    elif config.sigma_mode == "robust":
        sigma, fitted, fallback = estimate_noise(
            d, mask, focal_scale(rig.K), gauss_coverage(thresholds.alpha_tau)
        )
    else:
        sigma, fallback = thresholds.sigma_px, jnp.asarray(False)
    tau = tau_px(thresholds, sigma, fitted if config.tau_mode == "fitted" else None)
    return Scene(
        rig, xy, mask, mask.reshape(-1), d, dlt_blocks(rig, xy), sigma, tau, thresholds
    ), fallback


# --------------------------------------------------------------------------- the method


class ConfigMethods(Method):
    """What every C-DOG :class:`Config` does; its fields are the options its stage list
    declares (:func:`config_field_problems`)."""

    stages: ClassVar[tuple[Stage, ...]]
    options: ClassVar[dict]  # name -> OptionSpec, in field order
    thresholds_type: ClassVar[type]
    ranges: ClassVar[dict]
    units: ClassVar[dict]  # number -> "px", "px2" or "" (threshold_unit="focal" scales the lengths)

    def __post_init__(self):
        for name, spec in type(self).options.items():
            spec.check(getattr(self, name), type(self).__name__)
        if self.tau_mode == "fitted" and self.sigma_mode == "auto":
            raise ValueError(
                f"{type(self).__name__}.tau_mode='fitted' reads the robust fit: it needs sigma_mode='robust' (or 'given'); got sigma_mode='auto'"
            )

    @classmethod
    def paper(cls, **overrides) -> Config:
        """The paper's C-DOG (Alg. 1–3 and §IV-E) with noise-matched τ."""
        return cls(**overrides)

    @classmethod
    def extended(cls, **overrides) -> Config:
        """Beyond the paper: union adjacency, then leftover detections are attached to groups
        by reprojection (``recover``) and what is still left is associated again
        (``regroup``). Recovers most points the paper's pruning loses (2-view points above all)."""
        base = dict(adjacency="union", recover=True, recover_frac=2.0, regroup=True)
        base.update(overrides)
        return cls(**base)

    @classmethod
    def best(cls, **overrides) -> Config:
        """Our most accurate C-DOG, the default: the union graph with δ-pruning, recovery by
        reprojection (``recover``), then groups seeded from two-view hypotheses on what is
        still left (``seed``; a pair whose point other views see with no detection near is
        refused unless the scene's miss rate makes those misses plausible), rounds of
        nearest-point re-assignment with merging of split groups (``reassign``), and seeding
        once more on what those rounds detached. Leaves few detections unassigned at large
        σ, where pruning leaves most of a dense scene over (docs/ALGORITHM.md §8f–8g). For
        precision, groups that views seeing their point do not detect are dropped
        (``support_filter`` at 1.5 τ, ``support_alpha`` 0.07) and each group of ≥ 3 detaches
        a member that another detection fits as well (``detach_ambiguous``; §8d, §8h). The
        IQR, the BPE filter and regrouping of :meth:`extended` are left out: after seeding
        and re-assignment they changed neither real detections (Shelf) nor the synthetic
        grid, except for the worse (experiments/RESULTS.md, "Every stage of best()")."""
        base = dict(
            adjacency="union",
            iqr=False,
            bpe_filter=False,
            recover=True,
            recover_frac=2.0,
            seed=True,
            reassign=True,
            support_filter=True,
            support_frac=1.5,
            support_alpha=0.07,
            detach_ambiguous=True,
        )
        base.update(overrides)
        return cls(**base)

    @classmethod
    def reference(cls, **overrides) -> Config:
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

    def replace(self, **changes) -> Config:
        """A copy with ``changes`` applied; checked like a new Config."""
        return _derived(self, "replace", changes)

    def thresholds(self, sigma_px=0.0, *, dtype=None) -> Thresholds:
        """The numeric fields (and σ) as a :class:`Thresholds` of scalar arrays.

        NumPy scalars (cheap to pass to a jitted function), except that a JAX ``sigma_px``
        (traced, or batched) stays a JAX array.
        """
        dtype = np.dtype(jax.dtypes.canonicalize_dtype(dtype or jnp.float32))
        values = {name: np.asarray(getattr(self, name), dtype) for name in _numbers(type(self))}
        sigma = (
            jnp.asarray(sigma_px, dtype)
            if isinstance(sigma_px, jax.Array)
            else np.asarray(sigma_px, dtype)
        )
        return type(self).thresholds_type(sigma_px=sigma, **values)

    def structure(self) -> Config:
        """This config with its numeric fields reset to the defaults: the part a jit key needs."""
        defaults = {name: type(self).options[name].default for name in _numbers(type(self))}
        return _derived(self, "structure", defaults)

    def check_thresholds(self, thresholds: Thresholds) -> None:
        """Raise for a concrete threshold outside its range (:data:`RANGES`)."""
        check_thresholds(thresholds, type(self).thresholds_type, type(self).ranges)

    def associate_scene(self, rig, observations: Observations, thresholds: Thresholds):
        """C-DOG on one scene (:func:`cdog_jax.associate_traced`); ``observations.weights``
        are applied by the callers when the final points are triangulated."""
        return associate_traced(rig, observations.xy, observations.mask, thresholds, self)

    def table_bytes(self, num_views: int, itemsize: int) -> float:
        """Bytes per ``N²`` at the peak of one scene, by the stages that run (the coefficients
        were checked against XLA's ``memory_analysis()`` of the programs the library
        compiles, ALGORITHM.md §14)."""
        f = float(itemsize)
        # d and its masked copy, the proposal/adjacency bool tables, and (above N ≈ 10⁴, where
        # XLA stops reusing some of them) about 2 more bytes per pair; d stays alive to the
        # end, where the validity gate looks for rivals in it (one more float table).
        stages = [3.0 * f + 5.0]
        if self.second_association and COMPILER_OPTIONS is None:
            # (G, M, N) distances beside d, which XLA's YNN kernels take as a table of their
            # own; XLA's own kernels (the library's programs, xla_kernels.py) fuse them into
            # their minimum over the views.
            stages.append(f * (num_views / 2.0 + 1.0))
        if self.recover or self.regroup or self.seed:
            # d kept for regrouping, (G, N, 2) differences. Seeding builds its hypotheses 8
            # free detections at a time; recovery, re-assignment and merging measure 64 group
            # rows at a time; the support filter's and refinement's tables are linear in N
            # (XLA's figure at 10 × 1,000 slots: 17.2 bytes per pair for every preset).
            stages.append(3.0 * f + 6.0)
        return max(stages)


def _numbers(config_type: type) -> tuple[str, ...]:
    return tuple(name for name, spec in config_type.options.items() if spec.kind == NUMERIC)


def _declarations(stages: tuple[Stage, ...]) -> dict:
    """What a config class of C-DOG run as ``stages`` holds besides its fields: the stage
    list, every declared option (name -> OptionSpec, structural first), the ``Thresholds``
    type of its numbers, their ranges and units."""
    options = declared_options((SCENE, *stages))
    return {
        "stages": stages,
        "options": options,
        "thresholds_type": make_thresholds_type(options, __name__),
        "ranges": ranges(options),
        "units": units(options),
    }


def _fields_doc(options: dict, stages: tuple[Stage, ...]) -> str:
    return describe(options, (SCENE, *stages))


_CONFIG_HEAD = """C-DOG, the method: its options and presets. Structural options change the compiled
program; numbers do not (they become a traced :class:`Thresholds`, :meth:`thresholds`).

Each option is declared once, by the stage that reads it (``graph/``, ``refine/``; the
stage list is :data:`cdog_jax.STAGES`, docs/ARCHITECTURE.md), and written here as a field,
under its stage, with its default; a field that no stage declares, or a declared option
without its field, stops the import (:func:`config_field_problems`).

Presets: :meth:`paper` (the paper's method, our defaults), :meth:`extended` (beyond the
paper), :meth:`best` (the most accurate; the default method of ``associate``) and
:meth:`reference` (the original public implementation's behaviour, docs/BENCHMARK.md §5).

Each field, with its default, under its stage (static: part of the jit key; traced: a
number):

"""


# no_type_check: the options are checked by ``__post_init__`` (the declared rule, one message
# naming the field and what it allows); a test-time type checker must not pre-empt it.
@typing.no_type_check
@dataclasses.dataclass(frozen=True)
class Config(ConfigMethods):
    __doc__ = _CONFIG_HEAD  # and the fields, listed from the declarations below the class

    # scene: where σ comes from, the gate τ and the unit of lengths -------------------------
    # σ given by the caller ("given"), or estimated from the scene's epipolar distances
    # ("auto": a half-normal fit; "robust": half-t fits too; ALGORITHM.md §0.1).
    sigma_mode: SigmaMode = "given"
    # τ from σ and the two numbers below ("gaussian"), or the fitted quantile of the
    # true-pair distance ("fitted", with sigma_mode="robust" only).
    tau_mode: TauMode = "gaussian"
    # Lengths in pixels ("px"), or in pixels of a camera of focal length 1000 px ("focal").
    threshold_unit: ThresholdUnit = "px"
    # Traced, ≥ 0: the gate τ = max(alpha_tau · √2 · σ, tau_min_px).
    alpha_tau: float = 2.0
    # Traced, ≥ 0, pixels: the gate's lower bound.
    tau_min_px: float = 1.0

    # graph: the epipolar graph, its components and δ-overlap pruning (Alg. 1–2) -----------
    # An edge where both ends propose each other ("mutual") or either does ("union").
    adjacency: Adjacency = "mutual"
    # Which components δ-pruning may touch: all, those with a view conflict, or none.
    prune_scope: PruneScope = "all"
    # The most rounds of the component-splitting loop.
    max_split_iters: int = 64
    # Traced, in (0, 1]: the δ-overlap threshold (Alg. 2).
    delta: float = 0.5

    # iqr: outlier removal inside groups (Alg. 3) --------------------------------------------
    iqr: bool = True
    # A member's score: the mean error of the pairs without it ("exclude_own", the paper's)
    # or of all pairs ("include_own", the reference's).
    iqr_score: IqrScore = "exclude_own"
    # Quartiles of the scores and one 0 ("zero_pad"), or of the positive scores ("positive").
    iqr_quartiles: IqrQuartiles = "zero_pad"
    # The reference code's guards: iqr_min_px and iqr_force_px below.
    iqr_guards: bool = False
    # The most rounds of the removal loop.
    max_iqr_iters: int = 16
    # Traced, ≥ 0: the IQR fence multiplier.
    iqr_alpha: float = 2.0
    # Traced, ≥ 0, pixels: an outlier's score must also exceed this.
    iqr_floor_px: float = 1.0
    # Traced, ≥ 0, pixels (with iqr_guards): no outlier if the largest score is below this.
    iqr_min_px: float = 10.0
    # Traced, ≥ 0, pixels (with iqr_guards): the largest score is dropped above this.
    iqr_force_px: float = 50.0

    # second_association: leftover detections attached by epipolar cost (the reference's) ---
    second_association: bool = False
    # Traced, ≥ 0: attach where the mean cost is below second_frac · τ.
    second_frac: float = 0.5

    # bpe_filter: drop the groups after the first jump of the sorted BPEs --------------------
    bpe_filter: bool = True
    # Gaps needed before a jump can be declared.
    jump_min_gaps: int = 3
    # Traced, ≥ 0: a jump is a gap > jump_kappa · the median of the previous gaps ...
    jump_kappa: float = 10.0
    # Traced, ≥ 0, pixels²: ... and > jump_floor_px2 + (jump_floor_sigma · σ)².
    jump_floor_px2: float = 4.0
    # Traced, ≥ 0: see jump_floor_px2.
    jump_floor_sigma: float = 3.0

    # support: drop groups that views seeing their point do not detect ----------------------
    support_filter: bool = False
    # Traced, ≥ 0: a detection within support_frac · τ explains a view.
    support_frac: float = 3.0
    # Traced, in [0, 1]: drop a group where P(that many misses) < support_alpha.
    support_alpha: float = 0.01
    # Traced, in [0, 1]: the floor of the estimated miss rate.
    support_min_rate: float = 0.02
    # Traced, ≥ 0: members of the groups that estimate the miss rate.
    support_ref_views: float = 4.0

    # recover: leftovers attached to groups by reprojection (beyond the paper) ---------------
    recover: bool = False
    # Traced, ≥ 0: attach where the reprojection error is below recover_frac · τ.
    recover_frac: float = 1.0

    # regroup: Alg. 1–3 again on what is left (beyond the paper) -----------------------------
    regroup: bool = False

    # seed: groups from two-view hypotheses on what is still left (beyond the paper) ---------
    seed: bool = False
    # The fewest members (the pair and its voters) a seeded group needs; at least 2.
    seed_min_views: int = 2
    # Traced, > 0: a detection within seed_frac · τ votes for a two-view point.
    seed_frac: float = 1.5
    # Traced, > 0: a view that sees a two-view point with no detection within
    # seed_support_frac · τ counts against it (with the support filter, as in its test).
    seed_support_frac: float = 1.5

    # reassign: each detection to its nearest group point, refitting and merging ------------
    reassign: bool = False
    # The most rounds of re-assignment, refitting and merging (a round that changes nothing
    # ends them).
    reassign_iters: int = 3
    # Traced, > 0: a detection joins its nearest point within reassign_frac · τ.
    reassign_frac: float = 2.0

    # detach_ambiguous: from each group of ≥ 3, its worst member where another detection of
    # its view fits as well (beyond the paper) -----------------------------------------------
    detach_ambiguous: bool = False
    # Traced, ≥ 0: "as well" is within ambiguous_frac · τ.
    ambiguous_frac: float = 0.1

    # refine: each point refined by Levenberg–Marquardt --------------------------------------
    refine: bool = False
    # The solver's step bound.
    refine_max_steps: int = 20

    # validity_gate: in front of the cameras, enough parallax, bounded error ----------------
    # Traced, in [0, 90), degrees: the largest angle between members' lines of sight must
    # reach this.
    min_parallax_deg: float = 1.0
    # Traced, > 0: every member's reprojection error at most max_err_frac · τ.
    max_err_frac: float = 3.0


def _field_type(cls: type, field: dataclasses.Field) -> object:
    """The type of a dataclass field, its annotation string evaluated where it was written."""
    if not isinstance(field.type, str):
        return field.type
    owner = next(k for k in cls.__mro__ if field.name in vars(k).get("__annotations__", {}))
    return eval(field.type, vars(sys.modules[owner.__module__]))


def config_field_problems(cls: type, stages: tuple[Stage, ...]) -> list[str]:
    """How the fields written in the dataclass ``cls`` differ from the options that
    ``stages`` (and :data:`SCENE`) declare: a declared option without its field, a field
    that no stage declares, or a field whose type or default is not the declared one. Empty
    when they agree; :class:`Config` is checked when the module is imported."""
    options = declared_options((SCENE, *stages))
    fields = {f.name: f for f in dataclasses.fields(cls)}
    problems = []
    for name, spec in options.items():
        field = fields.get(name)
        if field is None:
            problems.append(f"{name}: declared by stage {spec.owner!r}; no field of {cls.__name__}")
            continue
        hint = _field_type(cls, field)
        if hint != spec.type:
            problems.append(
                f"{name}: type {field.type}; stage {spec.owner!r} declares {spec.type!r}"
            )
        if type(field.default) is not type(spec.default) or field.default != spec.default:
            problems.append(
                f"{name}: default {field.default!r}; stage {spec.owner!r} declares {spec.default!r}"
            )
    problems += [f"{name}: a field no stage declares" for name in fields if name not in options]
    return problems


for _name, _value in _declarations(STAGES).items():
    setattr(Config, _name, _value)
Config.__doc__ = _CONFIG_HEAD + _fields_doc(Config.options, STAGES)
if _problems := config_field_problems(Config, STAGES):
    raise TypeError("Config's fields differ from its stages' declarations: " + "; ".join(_problems))


_VARIANT_DOC = """A variant of :class:`Config` run as its own stage list (:func:`make_config`): its
fields are derived from those stages' declarations. Each field, with its default, under its
stage (static: part of the jit key; traced: a number):

"""


def make_config(stages: tuple[Stage, ...], *, name: str = "Config", base: type = Config) -> type:
    """A frozen, hashable dataclass of C-DOG run as ``stages`` (a test or an experiment
    adding a stage): one field per option the stages (and :data:`SCENE`) declare, with its
    default and its check, and the ``Thresholds`` type of its numbers; methods and presets
    those of ``base``."""
    namespace = _declarations(stages)
    options = namespace["options"]
    fields = [
        (n, spec.type, dataclasses.field(default=spec.default)) for n, spec in options.items()
    ]
    namespace.update(
        __module__=__name__, __qualname__=name, __doc__=_VARIANT_DOC + _fields_doc(options, stages)
    )
    return dataclasses.make_dataclass(name, fields, bases=(base,), namespace=namespace, frozen=True)


Thresholds = Config.thresholds_type
RANGES = Config.ranges
"""Every number's allowed range (``sigma_px`` included), from the stages' declarations."""

register_method("best", Config.best)
register_method("extended", Config.extended)
register_method("paper", Config.paper)
register_method("reference", Config.reference)
