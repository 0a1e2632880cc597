"""The public entry points: :func:`associate` (one scene) and :func:`associate_batch`.

Whatever the method (C-DOG's presets or any registered :class:`~cdog_jax.Method`), they
check the inputs eagerly, undistort, pad the shapes to a short ladder (``_runtime/shapes.py``),
compile the method's per-scene function once per shape (``jit``; ``vmap`` for batches, in
chunks so memory stays bounded), and finish with confidence weights, the minimum number of
views and the validity gate (:func:`finish_groups`, here too).
"""

from __future__ import annotations

from functools import partial

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from ._expect import INT, expect, expect_args
from ._method import Method, Observations, method_argument
from ._result import Association, association_from_groups
from ._runtime.devices import chunk_devices
from ._runtime.memory import check_memory
from ._runtime.shapes import (
    chunk_size,
    occupied_slots,
    pad_scenes,
    pad_slots,
    scene_capacity,
    slot_capacity,
    trim,
)
from ._runtime.stored_programs import call_stored
from ._runtime.xla_kernels import jit
from ._status import Status
from ._types import Array, ArrayLike, Float, Int
from ._validate import (
    as_array,
    check_batch_rig,
    check_observations,
    check_rig,
    check_sigma,
    check_threshold_shapes,
)
from .cdog._stage import raise_flag
from .geometry._camera import Rig
from .geometry._distortion import Fisheye, undistorted_checked
from .geometry._projection import group_errors
from .geometry._triangulate import triangulate_views_last
from .graph._groups import gather_groups
from .refine._validity import validity_gate


def check_thresholds_type(thresholds, method: Method, where: str) -> None:
    """``thresholds`` is None or of the type of ``method.thresholds()``."""
    kind = type(method.thresholds())
    if thresholds is not None and not isinstance(thresholds, kind):
        raise TypeError(
            f"{where}: thresholds must be {kind.__name__} or None; got {type(thresholds).__name__}"
        )


@partial(jit, static_argnames=("size",))
def _broadcast_row(value, size: int):
    """The first entry of ``value`` repeated ``size`` times, where ``value`` is."""
    return jnp.broadcast_to(jnp.reshape(value, (-1,))[0], (size,))


def _run_scene(rig, xy, mask, thresholds, method):
    """The method's per-scene function on plain observations (no weights)."""
    return method.associate_scene(rig, Observations(xy, mask), thresholds)


_associate_jit = jit(_run_scene, static_argnames=("method",))


def _prepare(method: Method, sigma, thresholds, dtype):
    """Static method and traced thresholds; ``sigma`` and ``thresholds`` are checked."""
    if thresholds is not None:
        method.check_thresholds(thresholds)
    if isinstance(sigma, str):
        if method.sigma_mode == "given":  # a method that estimates σ keeps its estimator
            method = method.replace(sigma_mode="auto")
        sigma = 0.0
    elif method.sigma_mode != "given":
        pass  # the method asks for the estimate; a given sigma is ignored
    if thresholds is None:
        thresholds = method.thresholds(sigma, dtype=dtype)
    else:
        thresholds = thresholds._replace(sigma_px=sigma)
    # NumPy scalars go to the jitted call as they are (cheaper than one device array each).
    np_dtype = np.dtype(jax.dtypes.canonicalize_dtype(dtype))
    thresholds = type(thresholds)(
        *(
            jnp.asarray(v, dtype) if isinstance(v, jax.Array) else np.asarray(v, np_dtype)
            for v in thresholds
        )
    )
    return method.structure(), thresholds


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
    method: Method | str | None = None,
    sigma: float | str = 1.0,
    thresholds: tuple | None = None,
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
        method: a :class:`~cdog_jax.Method` (e.g. a C-DOG :class:`~cdog_jax.Config`) or the
            name of a registered one (:func:`cdog_jax.method_names`): ``"best"`` (the
            default, the most accurate), ``"extended"``, ``"paper"`` (the paper's C-DOG), ``"reference"`` (the
            original code's choices), or any method registered with
            :func:`cdog_jax.register_method`.
        sigma: 2D noise std in pixels, or ``"auto"`` to estimate it (ALGORITHM.md §0.1; by
            the method's estimator when its ``sigma_mode`` is ``"robust"``).
        thresholds: overrides the method's numbers (``method.thresholds()``'s type; for
            sweeps, arrays welcome).
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

    The compiled program runs at a padded capacity: the smallest rung of the ladder 32, 64,
    128, 160, 192, 224, 256, 320, … that holds the slots in use (``P`` less the trailing
    slots no view fills), or the slots in use themselves where only that fits the memory
    budget, so that frames of different counts share a handful of programs (a first call at
    a new capacity compiles for seconds; up to 128 slots a scene runs in milliseconds at any
    of them); the result is brought back to ``P``.

    Returns:
        An :class:`Association` (labels, groups, points, errors). Its ``status`` is
        non-zero when a loop stopped at its bound or ``sigma="auto"`` fell back
        (:class:`cdog_jax.Status`, :func:`cdog_jax.check_status`).
    """
    expect_args("associate", rig=(rig, Rig))
    method = method_argument(method, "associate")
    check_thresholds_type(thresholds, method, "associate")
    xy, mask = as_array(xy), as_array(mask)
    check_rig(rig)
    check_observations(xy, mask, rig.num_views)
    check_sigma(sigma, rig, xy, mask)
    if thresholds is not None:
        check_threshold_shapes(thresholds, None)
    dtype = _float_dtype(xy)
    M, P = np.shape(mask)
    capacity = _capacity(
        "associate",
        M,
        occupied_slots(mask),
        method,
        dtype,
        1,
        memory_budget_gb,
        vmapped=None,
        ladder=scene_capacity,
    )
    static, thresholds = _prepare(method, sigma, thresholds, dtype)
    np_dtype = np.dtype(dtype)
    xy = pad_slots(np.asarray(xy, np_dtype), capacity, axis=1)
    mask = pad_slots(np.asarray(mask, bool), capacity, axis=1, fill=False)
    extras = _check_extras(dist, weights, min_views, (M, P), np_dtype)
    if not static.jittable:
        static.check_scene(mask, "associate")
        if extras is not None and extras[1] is not None:
            extras = (extras[0], pad_slots(extras[1], capacity, axis=1), extras[2])
        return trim(_associate_host(rig, xy, mask, thresholds, extras, static), P)
    if extras is not None:
        extras = (
            extras[0],
            None if extras[1] is None else pad_slots(extras[1], capacity, axis=1),
            extras[2],
        )
    return trim(_single_scene(rig, xy, mask, thresholds, extras, static), P)


def _single_scene(rig, xy, mask, thresholds, extras, method):
    """One padded scene through the method's compiled program; its lowered program is
    stored on disk for later processes (``_runtime/stored_programs.py``)."""
    if extras is None:
        return call_stored(_associate_jit, (rig, xy, mask, thresholds), method)
    return call_stored(_associate_extras_jit, (rig, xy, mask, thresholds, *extras), method)


def _capacity(
    where, M, P, method, dtype, batch_size, budget_gb, vmapped, ladder=slot_capacity
) -> int:
    """The padded slot capacity (``ladder(P)``: :func:`slot_capacity` or
    :func:`scene_capacity`), or ``P`` itself where only the unpadded shapes fit the memory
    budget; raises ``MemoryError`` where neither does. ``P``: the slots in use
    (:func:`occupied_slots`; one at least)."""
    P = max(int(P), 1)
    capacity = ladder(P)
    try:
        check_memory(where, M, capacity, method, dtype, batch_size, budget_gb, vmapped=vmapped)
    except MemoryError:
        check_memory(where, M, P, method, dtype, batch_size, budget_gb, vmapped=vmapped)
        return P
    return capacity


def check_min_views(min_views, num_views: int) -> None:
    """``min_views`` is an int in ``[2, num_views]``: a group needs two views and has at most
    one detection per view. Raises ``ValueError`` saying which bound it breaks."""
    if not isinstance(min_views, (int, np.integer)) or isinstance(min_views, bool) or min_views < 2:
        raise ValueError(
            f"min_views must be an int >= 2 (a group needs two views); got {min_views!r}"
        )
    if min_views > num_views:
        raise ValueError(
            f"min_views must be at most the number of views, {num_views} (no group has more); "
            f"got {min_views!r}"
        )


def _check_extras(dist, weights, min_views, mask_shape, dtype):
    """Checked ``(dist, weights, min_views)`` as NumPy arrays of ``dtype``, or None when all
    are defaults (then the plain pipeline runs)."""
    M = mask_shape[-2]
    check_min_views(min_views, M)
    if dist is None and weights is None and min_views == 2:
        return None
    if isinstance(dist, Fisheye):
        coeffs = np.asarray(dist.coeffs)
        if coeffs.shape != (M, 4) or not np.isfinite(coeffs).all():
            raise ValueError(
                f"dist: Fisheye coefficients must be finite with shape (M, 4) = ({M}, 4); got shape {coeffs.shape}"
            )
        dist = Fisheye(jnp.asarray(coeffs, dtype))
    elif dist is not None:
        dist_h = np.asarray(dist)
        if dist_h.shape != (M, 5):
            raise ValueError(
                f"dist must have shape (M, 5) = ({M}, 5), OpenCV (k1, k2, p1, p2, k3) per view; got {dist_h.shape}"
            )
        if not np.isfinite(dist_h).all():
            view = int(np.argwhere(~np.isfinite(dist_h))[0, 0])
            raise ValueError(f"dist of view {view} has non-finite entries")
        dist = np.asarray(dist, dtype)
    if weights is not None:
        w_h = np.asarray(weights)
        if w_h.shape != tuple(mask_shape):
            raise ValueError(
                f"weights must have the shape of mask {tuple(mask_shape)}; got {w_h.shape}"
            )
        bad = ~(np.isfinite(w_h) & (w_h >= 0))
        if bad.any():
            where = ", ".join(str(int(i)) for i in np.argwhere(bad)[0])
            raise ValueError(
                f"weights must be finite and >= 0; got {float(w_h[bad][0])!r} at index ({where})"
            )
        weights = np.asarray(weights, dtype)
    return dist, weights, np.asarray(min_views, np.int32)


# What happens after any method has associated one scene of real data: a pure, traced
# function (jit/vmap it), used by associate and associate_batch.
def finish_groups(
    rig: Rig,
    xy: Float[Array, "M P 2"],
    result: Association,
    weights: Float[Array, "M P"] | None,
    min_views: Int[Array, ""],
    thresholds: tuple,
) -> Association:
    """``result`` with groups of fewer than ``min_views`` views dropped (their detections
    become unassigned) and, when ``weights (M, P)`` is given (e.g. detector confidence, ≥ 0),
    every point re-triangulated by DLT with each member's equation scaled by its weight.

    BPE and the mean error stay the plain (unweighted) means over members;
    ``xy`` are the pixels the association used (undistorted). The groups then pass the
    validity gate again (`refine/_validity.py`, with ``thresholds.max_err_frac``,
    ``thresholds.min_parallax_deg`` and the result's τ): a member of weight 0 does not count as a
    view, and a re-weighted point must still lie in front of its cameras with parallax and
    bounded errors. Groups are compacted to the front again and the labels rebuilt, as
    :func:`cdog_jax.associate` returns them.
    """
    P = xy.shape[1]
    keep = result.valid & (result.n_views >= min_views)
    groups = jnp.where(keep[:, None], result.groups, -1)
    member = keep[:, None] & (groups >= 0)  # (G, M)
    xy_g = gather_groups(groups, xy)  # (G, M, 2)
    X = result.points3d
    w_g = None
    if weights is not None:
        w_g = jnp.where(member, gather_groups(groups, weights), 0.0)
        X_w, ok = triangulate_views_last(rig, xy_g, member, weights=w_g)
        X = jnp.where(ok[:, None], X_w, X)  # fewer than 2 weighted views: the gate dissolves it
    member, keep, X = validity_gate(
        rig,
        xy_g,
        member,
        X,
        result.tau_px,
        thresholds.max_err_frac,
        thresholds.min_parallax_deg,
        weights=w_g,
    )
    keep = keep & (
        jnp.sum(member, axis=1, dtype=jnp.int32) >= min_views
    )  # detaching may leave fewer
    member = member & keep[:, None]
    groups = jnp.where(member, groups, -1)
    bpe, err_px = group_errors(rig, X, xy_g, member)
    return association_from_groups(
        groups, keep, member, X, bpe, err_px, P, result.sigma_px, result.tau_px, result.status
    )


def _associate_one(rig, xy, mask, thresholds, dist, weights, min_views, method):
    """One scene with undistortion before and :func:`finish_groups` after the method;
    ``dist``/``weights`` may be None (static absence)."""
    if dist is not None:
        xy, lens_failed = undistorted_checked(rig, xy, mask, dist)
    result = method.associate_scene(rig, Observations(xy, mask, weights), thresholds)
    if dist is not None:
        result = _flag_lens(result, lens_failed)
    return finish_groups(
        rig, jnp.where(mask[..., None], xy, 0.0), result, weights, min_views, thresholds
    )


def _flag_lens(result: Association, failed) -> Association:
    """``result`` with :attr:`Status.LENS_NOT_INVERTED` raised where ``failed``."""
    flag = raise_flag(failed, Status.LENS_NOT_INVERTED)
    return eqx.tree_at(lambda r: r.status, result, result.status | flag)


_undistorted_jit = jit(undistorted_checked)
_finish_jit = jit(finish_groups)


def _associate_host(rig, xy, mask, thresholds, extras, method):
    """One scene of a host method (``method.jittable`` False): undistortion and
    :func:`finish_groups` compiled as usual, the method itself called eagerly on host arrays."""
    if extras is None:
        return method.associate_scene(rig, Observations(xy, mask), thresholds)
    dist, weights, min_views = extras
    if dist is not None:
        xy, lens_failed = _undistorted_jit(rig, xy, mask, dist)
        xy = np.asarray(xy)
    result = method.associate_scene(rig, Observations(xy, mask, weights), thresholds)
    if dist is not None:
        result = _flag_lens(result, lens_failed)
    return _finish_jit(
        rig, np.where(mask[..., None], xy, 0.0), result, weights, min_views, thresholds
    )


@partial(jit, static_argnames=("method",))
def _associate_extras_jit(rig, xy, mask, thresholds, dist, weights, min_views, *, method):
    return _associate_one(rig, xy, mask, thresholds, dist, weights, min_views, method)


@partial(jit, static_argnames=("method", "shared_rig"))
def _associate_batch_jit(rig, xy, mask, thresholds, extras, *, method, shared_rig):
    """One chunk of scenes, vmapped (the caller loops over chunks, so memory stays bounded)."""
    if extras is None:
        run = lambda r, x, m, t, e: _run_scene(r, x, m, t, method)  # noqa: E731
    else:
        run = lambda r, x, m, t, e: _associate_one(r, x, m, t, e[0], e[1], e[2], method)  # noqa: E731
    # dist and min_views are shared by all scenes; weights are per scene.
    shared = None if extras is None else (extras[0], None, extras[2])
    per_scene = None if extras is None else extras[1]
    if shared_rig:
        one = lambda a: run(rig, a[0], a[1], a[2], _join(shared, a[3]))  # noqa: E731
        return jax.vmap(one)((xy, mask, thresholds, per_scene))
    one = lambda a: run(a[0], a[1], a[2], a[3], _join(shared, a[4]))  # noqa: E731
    return jax.vmap(one)((rig, xy, mask, thresholds, per_scene))


def _moved_to(a, device):
    """``a`` on ``device`` if it is a JAX array committed to another device, else ``a``."""
    if isinstance(a, jax.Array) and a.committed and a.devices() != {device}:
        return jax.device_put(a, device)
    return a


def _join(shared, weights):
    return None if shared is None else (shared[0], weights, shared[2])


def associate_batch(
    rig: Rig,
    xy: ArrayLike,  # (B, M, P, 2); checked eagerly
    mask: ArrayLike,  # (B, M, P) bool
    *,
    method: Method | str | None = None,
    sigma: float | str | Float[Array, " B"] = 1.0,
    thresholds: tuple | None = None,
    batch_size: int = 16,
    dist: ArrayLike | Fisheye | None = None,
    weights: ArrayLike | None = None,
    min_views: int = 2,
    memory_budget_gb: float | None = None,
) -> Association:
    """:func:`associate` for ``B`` scenes, ``batch_size`` at a time in one compiled program.

    The rig is shared (``K (M, 3, 3)``) or per scene (``K (B, M, 3, 3)``); ``sigma`` and the
    thresholds may be scalars or ``(B,)`` arrays. Scenes run ``batch_size`` at a time
    (vmapped), which bounds memory; fewer scenes run as the smallest rung of the same ladder
    that holds them, and ``P`` is padded to a rung of a ladder of slots, so few programs are
    compiled; scenes run one at a time (one scene, or ``batch_size=1``) run
    :func:`associate`'s program at its capacity. Every field of the result gains a leading
    ``B`` axis. ``dist (M, 5)`` and ``min_views`` are shared by all scenes, ``weights (B, M,
    P)`` are per scene. Inputs are checked as in :func:`associate`; an error names the scene.
    The memory budget counts ``batch_size`` scenes (see :func:`associate`); ``status`` is per
    scene.
    """
    return associate_batch_at(
        rig,
        xy,
        mask,
        method=method,
        sigma=sigma,
        thresholds=thresholds,
        batch_size=batch_size,
        dist=dist,
        weights=weights,
        min_views=min_views,
        memory_budget_gb=memory_budget_gb,
    )


def associate_batch_at(
    rig,
    xy,
    mask,
    *,
    method=None,
    sigma=1.0,
    thresholds=None,
    batch_size=16,
    dist=None,
    weights=None,
    min_views=2,
    memory_budget_gb=None,
    min_slots=0,
    on_host=False,
    untrimmed=False,
    shared_sigma=None,
    checked=False,
):
    """:func:`associate_batch` at a slot capacity of at least ``min_slots`` per view (the
    rung that holds it): a caller that must meet one compiled program on every call (a live
    loop) gives its capacity here; results are those of :func:`associate_batch`, as NumPy
    arrays with ``on_host`` (a caller that reads them on the host: no transfer back).
    ``untrimmed``: where one call of the program holds exactly the ``B`` scenes at the
    input's slots, its arrays as it returns them (on the device: a caller that hands them
    to another program), else as with ``on_host``. ``shared_sigma``: a JAX array whose first
    entry is every scene's σ (px), where the program that computed it left it, unchecked (the
    package's own fit; ``sigma`` is then ignored and the method must take σ as given): the
    association is queued behind that program instead of waiting for its answer here.
    ``checked``: ``xy`` and ``mask`` come from detections the caller has checked (their
    values are not read again)."""
    expect_args("associate_batch", rig=(rig, Rig))
    expect(batch_size, INT, "batch_size", "associate_batch")
    method = method_argument(method, "associate_batch")
    check_thresholds_type(thresholds, method, "associate_batch")
    xy, mask = as_array(xy), as_array(mask)
    shared = rig.K.ndim == 3
    check_rig(rig, batched=not shared)
    if not checked:
        check_observations(xy, mask, rig.num_views, batched=True)
    if batch_size < 1:
        raise ValueError(f"batch_size must be >= 1; got {batch_size}")
    B = xy.shape[0]
    check_batch_rig(rig, B)
    if shared_sigma is not None:
        if method.sigma_mode != "given":
            raise ValueError("shared_sigma: for a method that takes σ as given")
        sigma = 0.0  # the σ row of the thresholds: replaced by shared_sigma chunk by chunk
    check_sigma(sigma, rig, xy, mask, num_scenes=B)
    if thresholds is not None:
        check_threshold_shapes(thresholds, B)
    dtype = _float_dtype(xy)
    M, P = np.shape(mask)[1:]
    chunk = chunk_size(B, batch_size)
    in_use = max(occupied_slots(mask), int(min_slots))
    # Scene by scene, each runs associate's program (its capacity rung): a one-frame batch,
    # such as the command line's on one frame, and associate on that frame then compile,
    # store and load one program.
    one_at_a_time = chunk == 1 and not min_slots
    capacity = _capacity(
        "associate_batch",
        M,
        in_use,
        method,
        dtype,
        chunk,
        memory_budget_gb,
        vmapped=None if one_at_a_time else True,
        ladder=scene_capacity if one_at_a_time else slot_capacity,
    )
    static, thresholds = _prepare(method, sigma, thresholds, dtype)
    if dist is not None and not shared:
        raise ValueError(
            "dist needs a shared rig (K of shape (M, 3, 3)); undistort per-scene rigs yourself"
        )
    np_dtype = np.dtype(dtype)
    extras = _check_extras(dist, weights, min_views, tuple(np.shape(mask)), np_dtype)
    padded = -(-B // chunk) * chunk  # whole chunks; padded scenes repeat the last one
    xy = pad_scenes(pad_slots(np.asarray(xy, np_dtype), capacity, axis=2), padded)
    mask = pad_scenes(pad_slots(np.asarray(mask, bool), capacity, axis=2, fill=False), padded)
    # Every threshold of every scene in one table (a row each), padded at once: one array
    # padded per threshold took ~0.1 ms a call.
    table = np.empty((len(thresholds), padded), np_dtype)
    for row, value in zip(table, thresholds):
        row[:B] = np.asarray(value, np_dtype)
    table[:, B:] = table[:, B - 1 : B]  # padded scenes repeat the last one (pad_scenes)
    if shared_sigma is not None and (chunk == 1 or not static.jittable):
        # Scene by scene: the σ is read here (the vmapped chunks below take it as it is).
        table[thresholds._fields.index("sigma_px")] = np.asarray(shared_sigma).reshape(-1)[0]
        shared_sigma = None
    thresholds = type(thresholds)(*table)
    if not shared:
        rig_arrays = [pad_scenes(np.asarray(a), padded) for a in (rig.K, rig.R, rig.t)]
    if extras is not None and extras[1] is not None:
        extras = (extras[0], pad_scenes(pad_slots(extras[1], capacity, axis=2), padded), extras[2])
    results = []
    if not static.jittable:  # a host method: scene by scene, eagerly
        for b in range(B):
            static.check_scene(mask[b], f"associate_batch (scene {b})")
        for b in range(B):
            rig_b = rig if shared else Rig(*(jnp.asarray(a[b]) for a in rig_arrays))
            extras_b = (
                None
                if extras is None
                else (extras[0], None if extras[1] is None else extras[1][b], extras[2])
            )
            one = _associate_host(
                rig_b,
                xy[b],
                mask[b],
                type(thresholds)(*(v[b] for v in thresholds)),
                extras_b,
                static,
            )
            results.append(jax.tree.map(lambda a: np.asarray(a)[None], one))
        padded = 0
    elif chunk == 1:  # one scene at a time: the single-scene program (no vmap to trace)
        for b in range(B):
            rig_b = rig if shared else Rig(*(jnp.asarray(a[b]) for a in rig_arrays))
            thresholds_b = type(thresholds)(*(v[b] for v in thresholds))
            extras_b = (
                None
                if extras is None
                else (extras[0], None if extras[1] is None else extras[1][b], extras[2])
            )
            one = _single_scene(rig_b, xy[b], mask[b], thresholds_b, extras_b, static)
            results.append(jax.tree.map(lambda a: np.asarray(a)[None], one))
        padded = 0
    # Chunks go round-robin over the devices (several run at once where there are several);
    # each is dispatched without waiting for the previous one.
    devices = chunk_devices(padded // chunk)
    # Every chunk's σ row from the shared σ, on the device (one small program, no wait).
    sigma_row = None if shared_sigma is None else _broadcast_row(shared_sigma, chunk)
    for start, device in zip(range(0, padded, chunk), devices):
        part = slice(start, start + chunk)
        rig_part = rig if shared else Rig(*(jnp.asarray(a[part]) for a in rig_arrays))
        extras_part = (
            None
            if extras is None
            else (extras[0], None if extras[1] is None else extras[1][part], extras[2])
        )
        thresholds_part = type(thresholds)(*(v[part] for v in thresholds))
        if sigma_row is not None:
            thresholds_part = thresholds_part._replace(sigma_px=sigma_row)
        args = (rig_part, xy[part], mask[part], thresholds_part, extras_part)
        if device is None:
            results.append(call_stored(_associate_batch_jit, args, static, shared_rig=shared))
            continue
        # The chunk's device as the default one: its host arguments go there with the call
        # (jax.device_put of the argument tree costs about as much as a live frame's chunk).
        # Arrays committed to another device (a rig the caller placed) would hold the chunk
        # there: those are moved.
        args = jax.tree.map(lambda a: _moved_to(a, device), args)
        with jax.default_device(device):
            results.append(call_stored(_associate_batch_jit, args, static, shared_rig=shared))
    if len(results) > 1:
        results = [
            jax.tree.map(lambda *parts: np.concatenate([np.asarray(p) for p in parts]), *results)
        ]
    if untrimmed and results[0].labels.shape[:1] + results[0].labels.shape[2:] == (B, P):
        return results[0]
    return trim(results[0], P, num_scenes=B, on_host=on_host or untrimmed)
