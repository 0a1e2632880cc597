"""Calibration from detections alone: association alternated with :func:`refine_rig`, the
rig of each round feeding the next association (one ``lax.scan``, one compiled program)."""

from __future__ import annotations

import functools
from typing import NamedTuple

import jax
import jax.numpy as jnp

from .._expect import ARRAY, expect_args
from .._method import Method, Observations, method_argument
from .._result import Association
from .._types import Array, Bool, Float, Int
from ..geometry._camera import Rig
from ._refine_rig import _STATIC, RefineInfo, _check_xy, refine_rig


class CalibrationHistory(NamedTuple):
    """Per-round record of :func:`calibrate`.

    Attributes:
        bpe_before, bpe_after: ``(rounds,)`` px², as :class:`RefineInfo` (the plain BPE,
            which may rise in a round under a robust ``loss`` that still falls).
        num_groups_used: ``(rounds,)`` int, groups that informed the refinement (all scenes).
        mean_groups_found: ``(rounds + 1,)`` mean number of groups associated per scene.
        num_steps: ``(rounds,)`` int, Levenberg–Marquardt steps.
        converged: ``(rounds,)`` bool.
        rigs: the rig after each round, fields ``(rounds, M, ...)``.
        associations: the :class:`Association` of every scene before each round and with the
            final rig, fields ``(rounds + 1, S, ...)``.
    """

    bpe_before: Float[Array, " R"]
    bpe_after: Float[Array, " R"]
    num_groups_used: Int[Array, " R"]
    mean_groups_found: Float[Array, " R1"]
    num_steps: Int[Array, " R"]
    converged: Bool[Array, " R"]
    rigs: Rig
    associations: Association


def calibrate(
    rig: Rig,
    xy: Float[Array, "S M P 2"],
    mask: Bool[Array, "S M P"],
    *,
    thresholds: tuple,
    method: Method | str | None = None,
    rounds: int = 3,
    **refine_options,
) -> tuple[Rig, CalibrationHistory]:
    """Alternate association and :func:`refine_rig` for ``rounds`` rounds (``lax.scan``).

    Each round associates every scene with the current rig (the method's per-scene function,
    vmapped over scenes), then refines the rig from those groups; a last association with the
    final rig follows, so the history holds ``rounds + 1`` associations (the first with
    the starting rig). With a drifted rig the epipolar errors exceed the noise: associate
    with a gate that allows for them (``sigma_mode="auto"`` or a larger
    ``thresholds.sigma_px``) and prefer ``loss="huber"``, since early groups hold mistakes.
    Leaves of ``thresholds`` may be scalars or ``(rounds,)`` arrays (e.g. σ shrinking as the
    rig improves; the last association reuses the last entry).

    Args:
        rig: starting ``M`` cameras.
        xy: ``(S, M, P, 2)`` detections (pixels) of ``S`` scenes; ``mask (S, M, P)`` bool.
        thresholds: the method's thresholds (``method.thresholds(σ)``; cast to the dtype of
            ``xy``).
        method: any :class:`~cdog_jax.Method` or a registered name (static). ``rounds``
            static ≥ 1.
        **refine_options: keyword options of :func:`refine_rig`, all static but ``scale_px``.

    Returns:
        The rig after the last round and a :class:`CalibrationHistory`. Jit with ``method``,
        ``rounds`` and the static refine options in ``static_argnames``.
    """
    expect_args("calibrate", rig=(rig, Rig), xy=(xy, ARRAY), mask=(mask, ARRAY))
    method = method_argument(method, "calibrate", default=None)
    kind = type(method.thresholds())
    if not isinstance(thresholds, kind):
        raise TypeError(
            f"calibrate: thresholds must be {kind.__name__} (method.thresholds()); got {type(thresholds).__name__}"
        )
    if not isinstance(rounds, int) or rounds < 1:
        raise ValueError(f"rounds must be a Python int >= 1; got {rounds!r}")
    _check_xy(rig, xy)
    if mask.shape != xy.shape[:3]:
        raise ValueError(
            f"mask must have shape (S, M, P) = {xy.shape[:3]} from xy; got {mask.shape}"
        )
    unknown = sorted(set(refine_options) - set(_STATIC) - {"scale_px"})
    if unknown:
        raise TypeError(
            f"calibrate got unknown options {unknown}; refine_rig takes {_STATIC + ('scale_px',)}"
        )
    per_round = []
    for name, v in zip(kind._fields, thresholds):
        v = jnp.asarray(v, xy.dtype)
        if v.shape not in ((), (rounds,)):
            raise ValueError(
                f"thresholds.{name} must have shape () or (rounds,) = ({rounds},); got {v.shape}"
            )
        v = jnp.broadcast_to(v, (rounds,))
        per_round.append(jnp.concatenate([v, v[-1:]]))  # the final association reuses the last
    traced = {k: jnp.asarray(v, xy.dtype) for k, v in refine_options.items() if k == "scale_px"}
    static = tuple(sorted((k, v) for k, v in refine_options.items() if k != "scale_px"))
    return _calibrate(
        rig, xy, mask, kind(*per_round), traced, config=method.structure(), options=static
    )


@functools.partial(jax.jit, static_argnames=("config", "options"))
def _calibrate(rig, xy, mask, thresholds, traced, *, config, options):
    rounds = thresholds.sigma_px.shape[0] - 1

    def one_round(rig, step):
        i, th_i = step
        assoc = jax.vmap(lambda x, m: config.associate_scene(rig, Observations(x, m), th_i))(
            xy, mask
        )
        # The extra last step only associates (lax.cond runs one branch under jit).
        new_rig, info = jax.lax.cond(
            i < rounds,
            lambda: refine_rig(rig, xy, assoc.groups, assoc.valid, **dict(options), **traced),
            lambda: (rig, _no_refinement(xy.dtype)),
        )
        return new_rig, (info, new_rig, assoc)

    rig, (info, rigs, assoc) = jax.lax.scan(one_round, rig, (jnp.arange(rounds + 1), thresholds))
    history = CalibrationHistory(
        bpe_before=info.bpe_before[:rounds],
        bpe_after=info.bpe_after[:rounds],
        num_groups_used=info.num_groups[:rounds],
        mean_groups_found=jnp.mean(assoc.num_groups.astype(xy.dtype), axis=1),
        num_steps=info.num_steps[:rounds],
        converged=info.converged[:rounds],
        rigs=jax.tree_util.tree_map(lambda a: a[:rounds], rigs),
        associations=assoc,
    )
    return rig, history


def _no_refinement(dtype) -> RefineInfo:
    zero = jnp.zeros((), dtype)
    izero = jnp.zeros((), jnp.int32)
    return RefineInfo(zero, zero, izero, jnp.array(False), jnp.array(False), izero)
