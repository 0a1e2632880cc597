"""C-DOG end to end for one scene (docs/ALGORITHM.md, ALGORITHM.md), and the public entry points.

``associate_traced`` is the pure function (jit/vmap it yourself; ``config`` must be
static). ``associate`` checks its inputs eagerly and runs the jitted pipeline on one
scene; ``associate_batch`` runs many scenes in chunks of one compiled, vmapped program, so
memory stays bounded. Both pad their shapes to a short ladder (``_shapes.py``).
"""

from __future__ import annotations

from functools import partial

import jax
import jax.numpy as jnp
import numpy as np

from ._config import Config, Thresholds, check_thresholds, config_from, tau_px
from ._expect import INT, expect, expect_args
from ._memory import check_memory
from ._result import Association
from ._shapes import chunk_size, pad_scenes, pad_slots, slot_capacity, trim
from ._status import Status
from ._types import Array, ArrayLike, Bool, Float
from ._validate import as_array, check_batch_rig, check_observations, check_rig, check_sigma, check_threshold_shapes
from .geometry._camera import Rig
from .geometry._distortion import Fisheye
from .geometry._epipolar import epipolar_distances
from .geometry._projection import group_errors
from .geometry._triangulate import dlt_blocks, solve_normal_3x3
from .graph._adjacency import adjacency_from_edges, alive_edges, nearest_neighbour_edges
from .graph._components import component_view_counts, connected_components_capped
from .graph._groups import compact_groups, gather_groups, groups_from_labels, labels_from_groups
from .graph._overlap import edge_overlap, remove_edges
from .graph._sigma import estimate_sigma, focal_scale
from .graph._split import split_conflicts
from .refine._bpe_filter import bpe_jump_keep
from .refine._least_squares import refine_points
from .refine._outliers import remove_outliers
from .refine._attach import leftover_nodes
from .refine._recovery import recover_leftovers
from .refine._second_association import second_association
from .refine._support import support_keep
from .refine._validity import validity_gate
from ._postprocess import finish_groups, undistorted


def _group_fit(rig, xy_g, member, N_g, r_g, origin):
    """Multi-view DLT point, per-member reprojection errors, BPE (px²) and mean error (px)."""
    w = member.astype(N_g.dtype)
    X, ok = solve_normal_3x3(jnp.einsum("gm,gmij->gij", w, N_g), jnp.einsum("gm,gmi->gi", w, r_g))
    X = jnp.where(ok[:, None], X + origin[None, :], 0.0)
    return X, group_errors(rig, X, xy_g, member)


# The graph stage and the IQR run twice in extended() (regroup): as nested jits they are
# traced and lowered once and the second call reuses them.
@partial(jax.jit, static_argnames=("config",))
def _graph_groups(d, valid, tau, th, config):
    """Alg. 1–2 on the valid nodes: epipolar graph, δ-pruning, view-unique components;
    returns the group table ``(G, M)``, its validity ``(G,)`` and an int32 status ``()``."""
    M, P = d.shape[:2]
    N = M * P
    d = jnp.where(valid.reshape(M, P, 1, 1) & valid.reshape(1, 1, M, P), d, jnp.inf)
    node_view = jnp.arange(N, dtype=jnp.int32) // P
    edges = nearest_neighbour_edges(d, tau)
    A = adjacency_from_edges(edges, N, config.adjacency)
    theta = edge_overlap(edges, A, dtype=d.dtype)
    d_nodes = d.reshape(N, N)
    edge_dist = 0.5 * (d_nodes[edges.src, edges.dst] + d_nodes[edges.dst, edges.src])
    weak = alive_edges(edges, A) & (theta < th.delta)
    status = jnp.int32(0)
    if config.prune_scope == "conflicts":
        labels0, capped = connected_components_capped(edges, alive_edges(edges, A), N)
        status = _flag(capped, Status.COMPONENTS_CAPPED)
        counts = component_view_counts(labels0, node_view, valid, M)
        weak = weak & jnp.any(counts >= 2, axis=1)[labels0[edges.src]]
    elif config.prune_scope == "none":
        weak = jnp.zeros_like(weak)
    A = remove_edges(A, edges, weak)
    _, labels, split_status = split_conflicts(A, edges, theta, edge_dist, node_view, valid, M, config.max_split_iters)
    return (*groups_from_labels(labels, valid, M, P), status | split_status)


def _flag(condition, flag: Status):
    """``()`` int32: ``flag`` where ``condition`` holds, else 0."""
    return jnp.where(condition, jnp.int32(int(flag)), jnp.int32(0))


@partial(jax.jit, static_argnames=("config",))
def _iqr(rig, xy, groups, gvalid, blocks, th, config):
    """Alg. 3 on the group table; returns the cleaned table, validity and int32 status."""
    N_node, r_node, origin = blocks
    member, capped = remove_outliers(
        rig,
        gather_groups(groups, N_node),
        gather_groups(groups, r_node),
        origin,
        gather_groups(groups, xy),
        gvalid[:, None] & (groups >= 0),
        th,
        config,
    )
    return jnp.where(member, groups, -1), jnp.sum(member, dtype=jnp.int32, axis=1) >= 2, _flag(capped, Status.IQR_CAPPED)


def _merge_groups(groups_a, valid_a, groups_b, valid_b):
    """Two tables of disjoint groups as one of the same capacity (at most N/2 groups exist)."""
    G = groups_a.shape[0]
    groups = jnp.concatenate([groups_a, groups_b])
    valid = jnp.concatenate([valid_a, valid_b])
    groups, valid, _ = compact_groups(jnp.where(valid[:, None], groups, -1), valid)
    return groups[:G], valid[:G]


def associate_traced(
    rig: Rig,
    xy: Float[Array, "M P 2"],
    mask: Bool[Array, "M P"],
    thresholds: Thresholds,
    config: Config,
) -> Association:
    """The whole pipeline for one scene as a pure function; no input checks.

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
    valid = mask.reshape(-1)

    # Alg. 1–2: epipolar graph, δ-overlap pruning, view-unique components.
    d = epipolar_distances(rig, xy, mask)  # (M, P, M, P)
    if config.sigma_mode == "auto":
        sigma, fallback = estimate_sigma(d, mask, focal_scale(rig.K))
    else:
        sigma, fallback = th.sigma_px, jnp.asarray(False)
    status = jnp.where(fallback, jnp.int32(Status.SIGMA_FALLBACK), jnp.int32(0))
    tau = tau_px(th, sigma)
    groups, gvalid, graph_status = _graph_groups(d, valid, tau, th, config)
    status = status | graph_status

    # Alg. 3: IQR outlier removal on per-group DLT blocks.
    blocks = dlt_blocks(rig, xy)  # (M, P, 3, 3), (M, P, 3), origin
    origin = blocks[2]
    if config.iqr:
        groups, gvalid, iqr_status = _iqr(rig, xy, groups, gvalid, blocks, th, config)
        status = status | iqr_status
    if config.second_association:
        groups = second_association(d.reshape(M * P, M * P), groups, gvalid, valid, tau, th)

    def fit(groups, gvalid):
        member = gvalid[:, None] & (groups >= 0)
        xy_g = gather_groups(groups, xy)
        N_g, r_g = gather_groups(groups, blocks[0]), gather_groups(groups, blocks[1])
        X, errors = _group_fit(rig, xy_g, member, N_g, r_g, origin)
        return member, xy_g, X, errors

    # §IV-E: group BPE filter.
    member, xy_g, X, (bpe, err_px) = fit(groups, gvalid)
    if config.bpe_filter:
        gvalid = bpe_jump_keep(bpe, gvalid, sigma, th, config.jump_min_gaps)
    if config.support_filter:  # beyond the paper: groups of clutter
        gvalid = support_keep(rig, xy, mask, X, member, gvalid, tau, th)
    groups = jnp.where(gvalid[:, None], groups, -1)

    # Beyond the paper: attach leftovers by reprojection, then group what is still left.
    if config.recover:
        groups = recover_leftovers(rig, xy, mask, groups, gvalid, X, tau, th)
    if config.regroup:
        left = leftover_nodes(groups, gvalid, mask)
        new_groups, new_valid, graph_status = _graph_groups(d, left, tau, th, config)
        status = status | graph_status
        if config.iqr:
            new_groups, new_valid, iqr_status = _iqr(rig, xy, new_groups, new_valid, blocks, th, config)
            status = status | iqr_status
        groups, gvalid = _merge_groups(groups, gvalid, new_groups, new_valid)
    if config.recover or config.regroup:
        member, xy_g, X, (bpe, err_px) = fit(groups, gvalid)
        if config.support_filter:  # the regrouped and the grown groups
            gvalid = support_keep(rig, xy, mask, X, member, gvalid, tau, th)
            member = member & gvalid[:, None]

    if config.refine:
        X, capped = refine_points(rig, X, xy_g, member, config.refine_max_steps)
        status = status | _flag(capped, Status.REFINE_CAPPED)

    # One gate for every valid group, whatever stage made it (ALGORITHM.md §12).
    member, gvalid, X = validity_gate(
        rig, xy_g, member & gvalid[:, None], X, tau, th.max_err_frac, th.min_parallax_deg
    )
    bpe, err_px = group_errors(rig, X, xy_g, member)

    groups = jnp.where(member, groups, -1)
    groups, gvalid, order = compact_groups(groups, gvalid)
    keep = gvalid[:, None]
    return Association(
        labels=labels_from_groups(groups, gvalid, P),
        groups=groups,
        valid=gvalid,
        points3d=jnp.where(keep, X[order], 0.0),
        bpe=jnp.where(gvalid, bpe[order], 0.0),
        err_px=jnp.where(gvalid, err_px[order], 0.0),
        n_views=jnp.sum((groups >= 0), dtype=jnp.int32, axis=1),
        num_groups=jnp.sum(gvalid, dtype=jnp.int32),
        sigma_px=jnp.asarray(sigma, xy.dtype),
        tau_px=jnp.asarray(tau, xy.dtype),
        status=status,
    )


_associate_jit = jax.jit(associate_traced, static_argnames=("config",))


def _prepare(config: Config, sigma, thresholds: Thresholds | None, dtype):
    """Static config and traced thresholds; ``sigma`` and ``thresholds`` are checked."""
    if thresholds is not None:
        check_thresholds(thresholds)
    if isinstance(sigma, str):
        config = config.replace(sigma_mode="auto")
        sigma = 0.0
    elif config.sigma_mode == "auto":
        pass  # the config asks for the estimate; a given sigma is ignored
    if thresholds is None:
        thresholds = config.thresholds(sigma, dtype=dtype)
    else:
        thresholds = thresholds._replace(sigma_px=sigma)
    # NumPy scalars go to the jitted call as they are (cheaper than one device array each).
    np_dtype = np.dtype(jax.dtypes.canonicalize_dtype(dtype))
    thresholds = Thresholds(*(jnp.asarray(v, dtype) if isinstance(v, jax.Array) else np.asarray(v, np_dtype) for v in thresholds))
    return config.structure(), thresholds


def _float_dtype(xy):
    """The float dtype the pipeline runs in: ``xy``'s (canonical: float64 only with x64), or
    the default float for integers. From the dtype alone: a JAX array made from ``xy`` would
    be a compiled program per shape."""
    dtype = np.dtype(xy.dtype)
    return jax.dtypes.canonicalize_dtype(dtype if np.issubdtype(dtype, np.floating) else np.float64)


def associate(
    rig: Rig,
    xy: ArrayLike,  # (M, P, 2); checked eagerly with a clear message
    mask: ArrayLike,  # (M, P) bool
    *,
    config: Config | str = Config.extended(),
    sigma: float | str = 1.0,
    thresholds: Thresholds | None = None,
    dist: ArrayLike | Fisheye | None = None,
    weights: ArrayLike | None = None,
    min_views: int = 2,
    memory_budget_gb: float | None = None,
) -> Association:
    """Associate the detections of one scene and triangulate every group.

    Args:
        rig: the cameras (``M`` views).
        xy: ``(M, P, 2)`` detections (pixels); ``P`` is a padded capacity.
        mask: ``(M, P)`` bool, True where a slot holds a detection.
        config: structure and default thresholds, or a preset's name: ``"extended"`` (the
            default, our best), ``"paper"`` (the paper's method), ``"reference"`` (the
            original code's choices).
        sigma: 2D noise std in pixels, or ``"auto"`` to estimate it (ALGORITHM.md §0.1).
        thresholds: overrides the config's numeric thresholds (for sweeps; arrays welcome).
        dist: optional ``(M, 5)`` OpenCV distortion ``(k1, k2, p1, p2, k3)`` per view (or a
            :class:`cdog_jax.geometry.Fisheye`, OpenCV's fisheye model); ``xy``
            are then the distorted (as-detected) pixels and are undistorted first. The
            result's points and errors refer to the undistorted (pinhole) pixels.
        weights: optional ``(M, P)`` non-negative weights (e.g. detector confidence) of the
            members' DLT equations when the final points are triangulated.
        min_views: keep only groups seen in at least this many views (≥ 2).
        memory_budget_gb: refuse (``MemoryError``, before compiling) when the estimated
            peak memory exceeds this many GB; default: ``CDOG_JAX_MEMORY_BUDGET`` or 80 %
            of the device's (CPU: the machine's) memory (ALGORITHM.md §14).

    ``xy`` may be float32 or float64 (integers are converted to the default float dtype);
    float16, bfloat16, complex and bool are refused. ``sigma`` must be finite, ``>= 0`` and
    at most the image diagonal: twice the largest principal point of ``rig.K``, or the
    detections' extent ``hypot(max |x|, max |y|)`` where that is larger.

    The compiled program runs at a padded capacity (the smallest power of two ``>= P``, at
    least 32; ``P`` itself where only that fits the memory budget), so that frames of
    different counts share a handful of programs; the result is trimmed back to ``P``.

    Returns:
        An :class:`Association` (labels, groups, points, errors). Its ``status`` is
        non-zero when a loop stopped at its bound or ``sigma="auto"`` fell back
        (:class:`cdog_jax.Status`, :func:`cdog_jax.check_status`).
    """
    expect_args("associate", rig=(rig, Rig), thresholds=(thresholds, (Thresholds, type(None))))
    config = config_from(config, "associate")
    xy, mask = as_array(xy), as_array(mask)
    check_rig(rig)
    check_observations(xy, mask, rig.num_views)
    check_sigma(sigma, rig, xy, mask)
    if thresholds is not None:
        check_threshold_shapes(thresholds, None)
    dtype = _float_dtype(xy)
    M, P = np.shape(mask)
    capacity = _capacity("associate", M, P, config, dtype, 1, memory_budget_gb, vmapped=None)
    static, th = _prepare(config, sigma, thresholds, dtype)
    np_dtype = np.dtype(dtype)
    xy = pad_slots(np.asarray(xy, np_dtype), capacity, axis=1)
    mask = pad_slots(np.asarray(mask, bool), capacity, axis=1, fill=False)
    extras = _check_extras(dist, weights, min_views, (M, P), np_dtype)
    if extras is None:
        result = _associate_jit(rig, xy, mask, th, config=static)
    else:
        dist, weights, min_views = extras
        weights = None if weights is None else pad_slots(weights, capacity, axis=1)
        result = _associate_extras_jit(rig, xy, mask, th, dist, weights, min_views, config=static)
    return trim(result, P)


def _capacity(where, M, P, config, dtype, batch_size, budget_gb, vmapped) -> int:
    """The padded slot capacity (:func:`slot_capacity`), or ``P`` itself where only the
    unpadded shapes fit the memory budget; raises ``MemoryError`` where neither does."""
    capacity = slot_capacity(P)
    try:
        check_memory(where, M, capacity, config, dtype, batch_size, budget_gb, vmapped=vmapped)
    except MemoryError:
        check_memory(where, M, P, config, dtype, batch_size, budget_gb, vmapped=vmapped)
        return P
    return capacity


def _check_extras(dist, weights, min_views, mask_shape, dtype):
    """Checked ``(dist, weights, min_views)`` as NumPy arrays of ``dtype``, or None when all
    are defaults (then the plain pipeline runs)."""
    if not isinstance(min_views, (int, np.integer)) or isinstance(min_views, bool) or min_views < 2:
        raise ValueError(f"min_views must be an int >= 2 (a group needs two views); got {min_views!r}")
    if dist is None and weights is None and min_views == 2:
        return None
    M = mask_shape[-2]
    if isinstance(dist, Fisheye):
        coeffs = np.asarray(dist.coeffs)
        if coeffs.shape != (M, 4) or not np.isfinite(coeffs).all():
            raise ValueError(f"dist: Fisheye coefficients must be finite with shape (M, 4) = ({M}, 4); got shape {coeffs.shape}")
        dist = Fisheye(jnp.asarray(coeffs, dtype))
    elif dist is not None:
        dist_h = np.asarray(dist)
        if dist_h.shape != (M, 5):
            raise ValueError(f"dist must have shape (M, 5) = ({M}, 5), OpenCV (k1, k2, p1, p2, k3) per view; got {dist_h.shape}")
        if not np.isfinite(dist_h).all():
            view = int(np.argwhere(~np.isfinite(dist_h))[0, 0])
            raise ValueError(f"dist of view {view} has non-finite entries")
        dist = np.asarray(dist, dtype)
    if weights is not None:
        w_h = np.asarray(weights)
        if w_h.shape != tuple(mask_shape):
            raise ValueError(f"weights must have the shape of mask {tuple(mask_shape)}; got {w_h.shape}")
        bad = ~(np.isfinite(w_h) & (w_h >= 0))
        if bad.any():
            where = ", ".join(str(int(i)) for i in np.argwhere(bad)[0])
            raise ValueError(f"weights must be finite and >= 0; got {float(w_h[bad][0])!r} at index ({where})")
        weights = np.asarray(weights, dtype)
    return dist, weights, np.asarray(min_views, np.int32)


def _associate_one(rig, xy, mask, th, dist, weights, min_views, config):
    """One scene with undistortion before and :func:`finish_groups` after the pipeline;
    ``dist``/``weights`` may be None (static absence)."""
    if dist is not None:
        xy = undistorted(rig, xy, mask, dist)
    result = associate_traced(rig, xy, mask, th, config)
    return finish_groups(rig, jnp.where(mask[..., None], xy, 0.0), result, weights, min_views, th)


@partial(jax.jit, static_argnames=("config",))
def _associate_extras_jit(rig, xy, mask, th, dist, weights, min_views, *, config):
    return _associate_one(rig, xy, mask, th, dist, weights, min_views, config)


@partial(jax.jit, static_argnames=("config", "shared_rig"))
def _associate_batch_jit(rig, xy, mask, th, extras, *, config, shared_rig):
    """One chunk of scenes, vmapped (the caller loops over chunks, so memory stays bounded)."""
    if extras is None:
        run = lambda r, x, m, t, e: associate_traced(r, x, m, t, config)  # noqa: E731
    else:
        run = lambda r, x, m, t, e: _associate_one(r, x, m, t, e[0], e[1], e[2], config)  # noqa: E731
    # dist and min_views are shared by all scenes; weights are per scene.
    shared = None if extras is None else (extras[0], None, extras[2])
    per_scene = None if extras is None else extras[1]
    if shared_rig:
        one = lambda a: run(rig, a[0], a[1], a[2], _join(shared, a[3]))  # noqa: E731
        return jax.vmap(one)((xy, mask, th, per_scene))
    one = lambda a: run(a[0], a[1], a[2], a[3], _join(shared, a[4]))  # noqa: E731
    return jax.vmap(one)((rig, xy, mask, th, per_scene))


def _join(shared, weights):
    return None if shared is None else (shared[0], weights, shared[2])


def associate_batch(
    rig: Rig,
    xy: ArrayLike,  # (B, M, P, 2); checked eagerly
    mask: ArrayLike,  # (B, M, P) bool
    *,
    config: Config | str = Config.extended(),
    sigma: float | str | Float[Array, " B"] = 1.0,
    thresholds: Thresholds | None = None,
    batch_size: int = 16,
    dist: ArrayLike | Fisheye | None = None,
    weights: ArrayLike | None = None,
    min_views: int = 2,
    memory_budget_gb: float | None = None,
) -> Association:
    """:func:`associate` for ``B`` scenes, ``batch_size`` at a time in one compiled program.

    The rig is shared (``K (M, 3, 3)``) or per scene (``K (B, M, 3, 3)``); ``sigma`` and the
    thresholds may be scalars or ``(B,)`` arrays. Scenes run ``batch_size`` at a time
    (vmapped), which bounds memory; fewer scenes run as the smallest power of two that
    holds them, and ``P`` is padded as in :func:`associate`, so few programs are compiled. Every field of the result gains a
    leading ``B`` axis. ``dist (M, 5)`` and ``min_views`` are shared by all scenes,
    ``weights (B, M, P)`` are per scene. Inputs are checked as in :func:`associate`; an
    error names the scene. The memory budget counts ``batch_size`` scenes (see
    :func:`associate`); ``status`` is per scene.
    """
    expect_args("associate_batch", rig=(rig, Rig), thresholds=(thresholds, (Thresholds, type(None))))
    expect(batch_size, INT, "batch_size", "associate_batch")
    config = config_from(config, "associate_batch")
    xy, mask = as_array(xy), as_array(mask)
    shared = rig.K.ndim == 3
    check_rig(rig, batched=not shared)
    check_observations(xy, mask, rig.num_views, batched=True)
    if batch_size < 1:
        raise ValueError(f"batch_size must be >= 1; got {batch_size}")
    B = xy.shape[0]
    check_batch_rig(rig, B)
    check_sigma(sigma, rig, xy, mask, num_scenes=B)
    if thresholds is not None:
        check_threshold_shapes(thresholds, B)
    dtype = _float_dtype(xy)
    M, P = np.shape(mask)[1:]
    chunk = chunk_size(B, batch_size)
    capacity = _capacity("associate_batch", M, P, config, dtype, chunk, memory_budget_gb, vmapped=True)
    static, th = _prepare(config, sigma, thresholds, dtype)
    if dist is not None and not shared:
        raise ValueError("dist needs a shared rig (K of shape (M, 3, 3)); undistort per-scene rigs yourself")
    np_dtype = np.dtype(dtype)
    extras = _check_extras(dist, weights, min_views, tuple(np.shape(mask)), np_dtype)
    padded = -(-B // chunk) * chunk  # whole chunks; padded scenes repeat the last one
    xy = pad_scenes(pad_slots(np.asarray(xy, np_dtype), capacity, axis=2), padded)
    mask = pad_scenes(pad_slots(np.asarray(mask, bool), capacity, axis=2, fill=False), padded)
    th = Thresholds(*(pad_scenes(np.broadcast_to(np.asarray(v, np_dtype), (B,)), padded) for v in th))
    if not shared:
        rig_arrays = [pad_scenes(np.asarray(a), padded) for a in (rig.K, rig.R, rig.t)]
    if extras is not None and extras[1] is not None:
        extras = (extras[0], pad_scenes(pad_slots(extras[1], capacity, axis=2), padded), extras[2])
    results = []
    if chunk == 1:  # one scene at a time: the single-scene program (no vmap to trace)
        for b in range(B):
            rig_b = rig if shared else Rig(*(jnp.asarray(a[b]) for a in rig_arrays))
            th_b = Thresholds(*(v[b] for v in th))
            if extras is None:
                one = _associate_jit(rig_b, xy[b], mask[b], th_b, config=static)
            else:
                one = _associate_extras_jit(
                    rig_b, xy[b], mask[b], th_b, extras[0], None if extras[1] is None else extras[1][b], extras[2],
                    config=static,
                )
            results.append(jax.tree.map(lambda a: np.asarray(a)[None], one))
        padded = 0
    for start in range(0, padded, chunk):
        part = slice(start, start + chunk)
        rig_part = rig if shared else Rig(*(jnp.asarray(a[part]) for a in rig_arrays))
        extras_part = None if extras is None else (extras[0], None if extras[1] is None else extras[1][part], extras[2])
        results.append(_associate_batch_jit(
            rig_part, xy[part], mask[part], Thresholds(*(v[part] for v in th)), extras_part,
            config=static, shared_rig=shared,
        ))
    if len(results) > 1:
        results = [jax.tree.map(lambda *parts: np.concatenate([np.asarray(p) for p in parts]), *results)]
    return trim(results[0], P, num_scenes=B)
