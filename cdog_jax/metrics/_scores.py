"""The paper's association metrics (docs/BENCHMARK.md §2, paper §V-A): G-, mP-, PG- scores, 3DErr, BPE.

One scene at a time, pure JAX with fixed shapes, so ``jax.jit`` and
``jax.vmap(scene_metrics, in_axes=(None, 0, 0))`` work; :func:`mean_metrics` averages a
batch on the host.

Conventions (where docs/BENCHMARK.md §2 leaves a choice):

- A *predicted group* is a valid group of the result holding ≥ 1 valid detection, or an
  unassigned valid detection as a singleton. Membership comes from ``result.labels``; a
  label that points at an invalid group counts as unassigned. Padded slots (``mask``
  False) are ignored whatever their labels, instances or pixels hold.
- ``g(p)`` is the majority vote over the ids ``-1, 0, 1, …`` of ``p``'s nodes, clutter
  (a valid detection with ``instance = -1``) voting ``-1``; ties go to the smallest id, so
  a tie between clutter and an instance gives ``-1``, which never matches.
- Ground truth is what the scene detects: an instance is a ground-truth group when it has
  ≥ 2 valid detections, and ``|g|`` counts those only. With missed detections
  (``generate_scene(drop_rate=...)``) a point visible in 3 views but detected in 2 has
  ``|g| = 2``, one detected once is no ground-truth group (its detection, like a clutter
  detection, is at best a correct singleton), and BPE averages over the detected views.
- Singletons never match anything (G- needs ≥ 2 nodes) and only count as G- false
  positives, so they are counted rather than tabulated: the contingency table is
  ``(G, I + 1)`` (groups × clutter and instance ids) instead of ``(G + N, I + 1)``.
- A group whose ``g(p)`` is ``-1`` scores ``TP_p = FN_p = 0`` in mP- (recall 0) and is left
  out of 3DErr and BPE (it has no ground-truth point); ``num_err_groups`` counts the groups
  those two average over.
- Every ratio whose denominator is 0 (no prediction, no ground-truth group, no group of
  ≥ 2 nodes) is 0, never NaN. ``err3d`` and ``bpe_px`` are 0 when ``num_err_groups`` is
  0; :func:`mean_metrics` then leaves the scene out of their average.
"""

from __future__ import annotations

import dataclasses

import equinox as eqx
import jax.numpy as jnp
import numpy as np

from .._expect import expect_args
from .._result import Association
from .._types import Array, Bool, Float, Int
from ..geometry._camera import Rig
from ..geometry._projection import project_views_last
from ..synthetic._scene import Scene


class Metrics(eqx.Module):
    """docs/BENCHMARK.md §2 scores of one scene (a batch of scenes adds leading axes to every field).

    Attributes:
        g_p, g_r, g_f1, g_iou: G- precision, recall, F1, IoU (imperfect groups allowed).
        mp_p, mp_r, mp_f1, mp_iou: mean over groups of ≥ 2 nodes of per-group point scores.
        pg_p, pg_r, pg_f1: perfect-group precision, recall, F1.
        err3d: mean ``‖X̂_p − X_g(p)‖`` (scene units) over the ``num_err_groups`` groups.
        bpe_px: mean over the same groups of the mean pixel distance between ``π_m(X̂_p)``
            and the noise-free projection of ``X_g(p)`` over the views that detect ``g(p)``.
        num_pred_groups: predicted groups with ≥ 2 nodes.
        num_gt_groups: instances with ≥ 2 valid detections.
        num_unassigned: valid detections in no valid group (the singletons).
        num_err_groups: groups of ≥ 2 nodes whose ``g(p)`` is an instance (not clutter).
        has_groups: ``num_pred_groups > 0``.
    """

    g_p: Float[Array, ""]
    g_r: Float[Array, ""]
    g_f1: Float[Array, ""]
    g_iou: Float[Array, ""]
    mp_p: Float[Array, ""]
    mp_r: Float[Array, ""]
    mp_f1: Float[Array, ""]
    mp_iou: Float[Array, ""]
    pg_p: Float[Array, ""]
    pg_r: Float[Array, ""]
    pg_f1: Float[Array, ""]
    err3d: Float[Array, ""]
    bpe_px: Float[Array, ""]
    num_pred_groups: Int[Array, ""]
    num_gt_groups: Int[Array, ""]
    num_unassigned: Int[Array, ""]
    num_err_groups: Int[Array, ""]
    has_groups: Bool[Array, ""]


def _ratio(num, den, dtype):
    """``num / den`` as ``dtype``, 0 where ``den == 0`` (the documented value of 0/0)."""
    num, den = num.astype(dtype), den.astype(dtype)
    ok = den > 0
    return jnp.where(ok, num / jnp.where(ok, den, 1.0), 0.0)


def _norm(v):
    """Euclidean norm over the last axis; safe (finite gradient) at 0."""
    sq = jnp.sum(v * v, axis=-1)
    pos = sq > 0
    return jnp.where(pos, jnp.sqrt(jnp.where(pos, sq, 1.0)), 0.0)


def _masked_mean(x, keep, dtype):
    """Mean of ``x`` over ``keep`` (last axis), 0 when nothing is kept."""
    return _ratio(jnp.sum(jnp.where(keep, x, 0.0), axis=-1), jnp.sum(keep, axis=-1), dtype)


def scene_metrics(rig: Rig, result: Association, scene: Scene) -> Metrics:
    """docs/BENCHMARK.md §2 metrics of one association result against its ground truth.

    Args:
        rig: the ``M`` cameras (used for BPE).
        result: the association of one scene (``labels (M, P)``, ``valid (G,)``,
            ``points3d (G, 3)``; the other fields are not read).
        scene: ground truth: ``mask (M, P)``, ``instance (M, P)`` (-1 for clutter),
            ``points3d (I, 3)`` indexed by instance id.

    Returns:
        A :class:`Metrics` of scalars; no field is NaN (see the module docstring for 0/0).
    """
    expect_args("scene_metrics", rig=(rig, Rig), result=(result, Association), scene=(scene, Scene))
    M, P = scene.mask.shape
    if result.labels.shape != (M, P):
        raise ValueError(
            f"result.labels must have shape (M, P) = {(M, P)} from the scene; got {result.labels.shape}"
        )
    G = result.valid.shape[0]
    I = scene.points3d.shape[0]
    dtype = rig.K.dtype

    mask = scene.mask
    labels = result.labels.astype(jnp.int32)
    inst = scene.instance.astype(jnp.int32)
    in_group = mask & (labels >= 0) & (labels < G) & result.valid[jnp.clip(labels, 0, G - 1)]
    is_inst = mask & (inst >= 0) & (inst < I)  # anything else that is valid votes as clutter
    inst_c = jnp.clip(inst, 0, I - 1)

    # Contingency table: column 0 is clutter (-1), column k + 1 is instance k, so the
    # first argmax is the majority with ties to the smallest id, -1 included.
    col = jnp.where(is_inst, inst_c + 1, 0)
    T = (
        jnp.zeros((G, I + 1), jnp.int32)
        .at[jnp.clip(labels, 0, G - 1), col]
        .add(in_group.astype(jnp.int32))
    )
    size = jnp.sum(T, axis=1)  # (G,) |p|
    g_col = jnp.argmax(T, axis=1)
    g = g_col.astype(jnp.int32) - 1  # (G,) g(p), -1 = clutter
    g_c = jnp.clip(g, 0, I - 1)
    tp = jnp.where(g >= 0, jnp.take_along_axis(T, g_col[:, None], axis=1)[:, 0], 0)  # |p ∩ g(p)|

    gt_count = (
        jnp.zeros((I,), jnp.int32).at[inst_c].add(is_inst.astype(jnp.int32))
    )  # |g| per instance
    num_gt = jnp.sum(gt_count >= 2).astype(jnp.int32)
    num_unassigned = jnp.sum(mask & ~in_group).astype(jnp.int32)
    multi = size >= 2
    num_multi = jnp.sum(multi).astype(jnp.int32)
    num_pred = jnp.sum(size >= 1).astype(jnp.int32) + num_unassigned  # singletons included

    def covered(flag):
        """Number of instances that at least one flagged group points at."""
        hit = jnp.zeros((I,), jnp.int32).at[g_c].add((flag & (g >= 0)).astype(jnp.int32))
        return jnp.sum(hit > 0).astype(jnp.int32)

    # G-: a group matches g(p) with ≥ 2 nodes of it, more than half of p. Which of several
    # matching groups an instance takes does not change the counts, only that it takes one.
    tp_g = covered((tp >= 2) & (2 * tp > size))
    g_p = _ratio(tp_g, num_pred, dtype)
    g_r = _ratio(tp_g, num_gt, dtype)
    g_f1 = _ratio(2 * tp_g, num_pred + num_gt, dtype)  # 2TP / (2TP + FP + FN)
    g_iou = _ratio(tp_g, num_pred + num_gt - tp_g, dtype)

    # mP-: per group TP_p, FP_p = |p| - TP_p, FN_p = |g(p)| - TP_p (0 for clutter).
    gt_size = jnp.where(g >= 0, gt_count[g_c], 0)
    mp_p = _masked_mean(_ratio(tp, size, dtype), multi, dtype)
    mp_r = _masked_mean(_ratio(tp, gt_size, dtype), multi, dtype)
    mp_f1 = _masked_mean(_ratio(2 * tp, size + gt_size, dtype), multi, dtype)
    mp_iou = _masked_mean(_ratio(tp, size + gt_size - tp, dtype), multi, dtype)

    # PG-: a perfect group holds nodes of one instance only.
    tp_pg = covered(multi & (tp == size))
    pg_p = _ratio(tp_pg, num_multi, dtype)
    pg_r = _ratio(tp_pg, num_gt, dtype)
    pg_f1 = _ratio(2 * tp_pg, num_multi + num_gt, dtype)

    # 3DErr and BPE over groups of ≥ 2 nodes with an instance as g(p).
    scored = multi & (g >= 0)
    X_hat = result.points3d.astype(dtype)
    X_gt = scene.points3d.astype(dtype)[g_c]  # (G, 3)
    err3d = _masked_mean(_norm(X_hat - X_gt), scored, dtype)
    views = jnp.broadcast_to(jnp.arange(M)[:, None], (M, P))
    detected = (
        jnp.zeros((I, M), jnp.int32).at[inst_c, views].add(is_inst.astype(jnp.int32))[g_c] > 0
    )  # (G, M)
    xy_hat, _ = project_views_last(rig, X_hat)  # (G, M, 2)
    xy_gt, _ = project_views_last(rig, X_gt)
    bpe_group = _masked_mean(_norm(xy_hat - xy_gt), detected, dtype)  # (G,)
    bpe_px = _masked_mean(bpe_group, scored, dtype)

    return Metrics(
        g_p=g_p,
        g_r=g_r,
        g_f1=g_f1,
        g_iou=g_iou,
        mp_p=mp_p,
        mp_r=mp_r,
        mp_f1=mp_f1,
        mp_iou=mp_iou,
        pg_p=pg_p,
        pg_r=pg_r,
        pg_f1=pg_f1,
        err3d=err3d,
        bpe_px=bpe_px,
        num_pred_groups=num_multi,
        num_gt_groups=num_gt,
        num_unassigned=num_unassigned,
        num_err_groups=jnp.sum(scored).astype(jnp.int32),
        has_groups=num_multi > 0,
    )


def mean_metrics(metrics: Metrics) -> dict[str, float]:
    """Average per-scene metrics over scenes (docs/BENCHMARK.md §2), on the host.

    Args:
        metrics: a :class:`Metrics` whose fields share any leading batch shape (``(B,)``
            from ``jax.vmap(scene_metrics, ...)``, or ``()`` for one scene).

    Returns:
        ``{field: mean}`` plus ``num_scenes``. Scores and counts are means over all scenes
        (a scene without groups contributes its zeros); ``has_groups`` becomes the fraction
        of scenes with a group; ``err3d`` and ``bpe_px`` are means over the scenes with
        ``num_err_groups > 0`` only, NaN when there is none.
    """
    expect_args("mean_metrics", metrics=(metrics, Metrics))
    leaves = {
        f.name: np.asarray(getattr(metrics, f.name)).reshape(-1)
        for f in dataclasses.fields(Metrics)
    }
    with_err = leaves["num_err_groups"] > 0
    out = {}
    for k, v in leaves.items():
        v = v.astype(np.float64)
        if k in ("err3d", "bpe_px"):
            out[k] = float(v[with_err].mean()) if with_err.any() else float("nan")
        else:
            out[k] = float(v.mean()) if v.size else float("nan")
    out["num_scenes"] = float(leaves["g_p"].size)
    return out
