"""Association of classed detections (keypoint types, marker colours, object categories).

Detections of different classes are never joined. Every (frame, class) pair with
detections in at least two views becomes one small scene of capacity ``P_c`` (the most
detections of one class in one view), and :func:`cdog_jax.associate_batch` runs all of
them in one compiled call; the groups are then mapped back to the input's slots, one
table of groups per frame, each group with its class (ALGORITHM.md §15).

Why scenes per class rather than one graph per frame with cross-class edges removed:
every stage (graph, IQR, recovery by reprojection, regrouping, support) then sees only
one class by construction, and the graph of a class costs ``(M · P_c)²`` instead of
``(M · C · P_c)²`` (``experiments/bench_classes.py`` measures both).
"""

from __future__ import annotations

import warnings
from functools import partial
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from .._associate import associate_batch_at, check_min_views
from .._expect import INT, expect, expect_args
from .._method import method_argument
from .._result import Association, batched_association
from .._runtime.devices import chunk_devices
from .._runtime.shapes import ladder_rung, slot_capacity
from .._runtime.stored_programs import call_stored
from .._runtime.xla_kernels import jit
from .._status import Status
from .._types import Array, Int
from .._validate import as_array, check_observations, check_rig
from ..cdog._config import REFERENCE_FOCAL_PX
from ..geometry._camera import Rig, cannot_change
from ..geometry._distortion import undistorted
from ..geometry._epipolar import epipolar_distances
from ..graph._sigma import FALLBACK_SIGMA_PX, focal_scale, nearest_samples, sigma_from_samples
from ..graph._sigma_robust import nearest_two_samples, robust_sigma_from_samples
from ._persons import check_instances, person_consistent, person_vote_argument

SIGMA_POOLS = ("frame", "all", "scene")


class ClassAssociation(NamedTuple):
    """What :func:`associate_classes` returns.

    Attributes:
        association: an :class:`Association` with a leading frame axis ``F``, in the input's
            slots: ``labels (F, M, P)``, ``groups (F, G, M)`` (slot of the member in each
            view, ``-1``), ``valid (F, G)``, ``points3d (F, G, 3)``, ``bpe``, ``err_px``,
            ``n_views (F, G)``, ``num_groups (F,)``, ``sigma_px``, ``tau_px`` and ``status``
            ``(F,)`` (flags of all the frame's classes). ``G`` is the most groups of any
            frame; valid groups come first, by class, then as the pipeline orders them.
        group_class: ``(F, G)`` int32 class id of every group, ``-1`` where not valid.
        class_names: the names by class id, or ``None``.
        num_classes: ``C``, the number of class ids.
    """

    association: Association
    group_class: np.ndarray
    class_names: tuple[str, ...] | None
    num_classes: int


class _Scenes(NamedTuple):
    """Detections regrouped into one scene per live (frame, class) pair."""

    xy: np.ndarray  # (B, M, Pc, 2)
    mask: np.ndarray  # (B, M, Pc)
    slot: np.ndarray  # (B, M, Pc) int64: the input slot of each scene slot, -1 padding
    frame: np.ndarray  # (B,) frame of each scene
    cls: np.ndarray  # (B,) class of each scene
    weights: np.ndarray | None  # (B, M, Pc)


class SceneResults(NamedTuple):
    """One frame's class scenes and their association before it is mapped to the frame
    (:func:`associate_classes_at` with ``scenes_only``)."""

    scenes: _Scenes
    result: Association  # (B, G, …) per scene: the association program's own arrays
    frame_flags: np.ndarray | None  # (1,) status bits of the frame beyond its scenes'
    fell_back: jax.Array | None = None  # the σ fit's fallback (first entry), not yet read

    def flags(self) -> np.ndarray | None:
        """``frame_flags``, with the σ fit's fallback once it is read (here)."""
        if self.fell_back is None:
            return self.frame_flags
        return fallback_flags(np.asarray(self.fell_back)[:1])


def fallback_flags(fell_back) -> np.ndarray:
    """Status bits of frames from their σ fits' fallbacks ``fell_back`` (read here): a frame
    whose σ fell back (too little evidence, or implausibly large) is flagged as a scene that
    estimates its own σ is."""
    return np.where(np.asarray(fell_back), np.int32(Status.SIGMA_FALLBACK), np.int32(0))


def associate_classes(
    rig: Rig,
    xy,
    mask,
    classes,
    *,
    class_names=None,
    num_classes: int | None = None,
    method=None,
    sigma: float | str = "auto",
    sigma_pool: str = "frame",
    dist=None,
    weights=None,
    min_views: int = 2,
    batch_size: int = 64,
    memory_budget_gb: float | None = None,
    instances=None,
    person_vote=None,
) -> ClassAssociation:
    """Associate detections that carry a class, every class of every frame in one call.

    Args:
        rig: the ``M`` cameras (shared by all frames).
        xy: ``(F, M, P, 2)`` detections (pixels, as detected when ``dist`` is given).
        mask: ``(F, M, P)`` bool.
        classes: ``(F, M, P)`` int class id ``>= 0`` of every detection (ignored where
            ``mask`` is False).
        class_names: optional names by class id (``C`` of them).
        num_classes: ``C``; default ``len(class_names)``, else the largest id + 1.
        method, dist, weights (``(F, M, P)``), min_views, memory_budget_gb: as in
            :func:`cdog_jax.associate_batch`.
        sigma: the noise σ in pixels, or ``"auto"``: estimated from the epipolar
            nearest-neighbour distances of all classes pooled (see ``sigma_pool``): one
            class in one view holds too few detections for its own estimate.
        sigma_pool: ``"frame"`` (one σ per frame, default), ``"all"`` (one for all frames)
            or ``"scene"`` (each (frame, class) scene its own, as ``associate_batch``).
        batch_size: the most scenes per compiled call (memory bound; scenes are small).
            Fewer scenes run as the smallest rung of a fine ladder (1, 2, 3, 4, 6, 8, 12,
            16, 24, 32, 48, …) that holds them, more in chunks of ``batch_size``, so a few
            compiled programs serve any number of frames and classes.
        instances: optional ``(F, M, P)`` int per-view instance index of every detection
            (the 2D skeleton it belongs to in its view, ``-1``: unknown).
        person_vote: make the groups of each frame consistent with ``instances`` (a
            person-level vote, then re-association of the joints that disagree;
            ALGORITHM.md §15.1): ``None`` (default): on when ``instances`` is given;
            ``True`` or a :class:`cdog_jax.PersonVote` (its numbers): on, ``instances``
            required; ``False``: off.

    Returns:
        A :class:`ClassAssociation`. Raises ``ValueError`` before any work for a wrong shape,
        a negative class or one ``>= num_classes``, names of the wrong length, or
        ``instances`` not integers ``>= -1`` of ``mask``'s shape.
    """
    return associate_classes_at(
        rig,
        xy,
        mask,
        classes,
        class_names=class_names,
        num_classes=num_classes,
        method=method,
        sigma=sigma,
        sigma_pool=sigma_pool,
        dist=dist,
        weights=weights,
        min_views=min_views,
        batch_size=batch_size,
        memory_budget_gb=memory_budget_gb,
        instances=instances,
        person_vote=person_vote,
    )


def associate_classes_at(
    rig,
    xy,
    mask,
    classes,
    *,
    class_names=None,
    num_classes=None,
    method=None,
    sigma="auto",
    sigma_pool="frame",
    dist=None,
    weights=None,
    min_views=2,
    batch_size=64,
    memory_budget_gb=None,
    instances=None,
    person_vote=None,
    min_scenes=0,
    min_slots=0,
    min_samples=0,
    min_vote_rows=8,
    on_host=False,
    scenes_only=False,
    checked=False,
):
    """:func:`associate_classes` with at least ``min_scenes`` scenes (empty ones added) of at
    least ``min_slots`` slots per view, the σ fit's table at least ``min_samples`` wide, the
    person vote's DLT tables at least ``min_vote_rows`` rows: a
    caller that must meet the same compiled programs on every call (a live loop) gives its
    shapes here; results are those of
    :func:`associate_classes`, up to the last bits of σ with ``sigma="auto"``; the
    association's fields NumPy arrays with ``on_host`` (for a caller that reads them on the
    host). ``scenes_only`` (one frame, no person vote): the class scenes' results before
    they are mapped to the frame, :class:`SceneResults` (``None`` for a frame without a
    scene), their arrays left where the program put them. ``checked``: the caller has checked
    the frames (``xy`` and ``mask`` as :func:`check_observations` wants them, ``classes``
    int64 ids below ``num_classes``, 0 outside the mask: a live loop, which checks each frame
    as it comes); they are not read again."""
    expect_args("associate_classes", rig=(rig, Rig))
    expect(batch_size, INT, "batch_size", "associate_classes")
    method = method_argument(method, "associate_classes")
    xy, mask = np.asarray(as_array(xy)), np.asarray(as_array(mask))
    check_rig(rig)
    if checked:
        C = int(num_classes)
    else:
        check_observations(xy, mask, rig.num_views, batched=True)
        classes = _check_classes(classes, mask)
        C = _num_classes(classes, mask, class_names, num_classes)
    vote = person_vote_argument(person_vote, instances)
    if scenes_only and (vote is not None or mask.shape[0] != 1):
        raise ValueError("scenes_only: one frame without the person vote")
    instances = None if instances is None else check_instances(instances, mask)
    if sigma_pool not in SIGMA_POOLS:
        raise ValueError(f"sigma_pool must be one of {SIGMA_POOLS}; got {sigma_pool!r}")
    if batch_size < 1:
        raise ValueError(f"batch_size must be >= 1; got {batch_size}")
    if weights is not None:
        weights = np.asarray(weights)
        if weights.shape != mask.shape:
            raise ValueError(
                f"weights must have the shape of mask {mask.shape}; got {weights.shape}"
            )
    if (
        getattr(method, "tau_mode", "gaussian") == "fitted"
        and method.sigma_mode == "robust"
        and sigma_pool != "scene"
    ):
        raise ValueError(
            f"tau_mode='fitted' fits the gate per scene: it needs sigma_pool='scene'; got sigma_pool={sigma_pool!r}"
        )
    F, M, P = mask.shape
    check_min_views(min_views, M)  # before the σ fit
    scenes = _regroup(xy, mask, classes, C, weights)
    B = len(scenes.frame)
    if B and (min_scenes or min_slots):
        scenes = _at_least(scenes, min_scenes, min_slots)
    if B == 0:
        return None if scenes_only else _empty(rig, F, M, P, xy.dtype, C, class_names, on_host)
    dtype = jax.dtypes.canonicalize_dtype(
        xy.dtype if np.issubdtype(xy.dtype, np.floating) else np.float64
    )
    auto = sigma == "auto" or method.sigma_mode != "given"
    queued = (  # one live frame: σ stays on the device, the association queued behind its fit
        auto
        and sigma_pool != "scene"
        and getattr(method, "threshold_unit", "px") == "px"
        and _one_table(F, scenes, min_samples)
    )
    shared_sigma = fit_fallback = None
    if queued:
        robust = method.sigma_mode == "robust"
        d = None if dist is None else np.asarray(dist, dtype)
        shared_sigma, fit_fallback = _one_table_fit(rig, scenes, d, dtype, robust, min_samples)
        method = method.replace(sigma_mode="given")
        sigma_arg, frame_flags = 0.0, None
    elif auto and sigma_pool != "scene":
        estimator = "robust" if method.sigma_mode == "robust" else "auto"
        frame_sigma, fell_back = _pooled_sigma(
            rig, scenes, F, dist, dtype, sigma_pool, estimator, min_samples
        )
        frame_flags = fallback_flags(fell_back)
        sigma_arg = np.asarray(frame_sigma[scenes.frame], dtype)
        if (
            getattr(method, "threshold_unit", "px") == "focal"
        ):  # the pipeline reads a given σ in focal lengths
            sigma_arg = np.asarray(
                sigma_arg * (REFERENCE_FOCAL_PX / np.asarray(_rig_focal(rig), dtype)),
                dtype,
            )
        method = method.replace(sigma_mode="given")
    else:
        sigma_arg = "auto" if auto else sigma
        frame_flags = None
    # associate_batch runs the scenes in chunks of a ladder rung (at most batch_size): few
    # compiled programs, whatever the number of frames and classes, and little padding.
    result = associate_batch_at(
        rig,
        scenes.xy.astype(dtype, copy=False),
        scenes.mask,
        method=method,
        sigma=sigma_arg,  # a NumPy σ per scene goes to the program as it is
        dist=dist,
        weights=None if weights is None else scenes.weights.astype(dtype, copy=False),
        min_views=min_views,
        batch_size=batch_size,
        memory_budget_gb=memory_budget_gb,
        min_slots=min_slots,
        on_host=True,
        untrimmed=scenes_only,
        shared_sigma=shared_sigma,
        # The class scenes are slots of the frame checked above (read again if cast).
        checked=np.dtype(xy.dtype) == np.dtype(dtype),
    )
    if scenes_only:
        return SceneResults(scenes, result, frame_flags, fit_fallback)
    if fit_fallback is not None:  # the association is done: the fit's fallback is read now
        frame_flags = fallback_flags(np.asarray(fit_fallback)[:1])
    out = _map_back(result, scenes, F, M, P, C, class_names, on_host, frame_flags)
    if vote is not None:
        fixed = person_consistent(
            rig,
            out.association,
            out.group_class,
            xy,
            mask,
            classes,
            instances,
            vote,
            dist=dist,
            weights=weights,
            min_views=min_views,
            min_rows=min_vote_rows,
        )
        a = out.association
        assoc = batched_association(
            on_host=on_host,
            **{k: v for k, v in fixed._asdict().items() if k != "group_class"},
            sigma_px=a.sigma_px,
            tau_px=a.tau_px,
            status=a.status,
        )
        out = out._replace(association=assoc, group_class=fixed.group_class)
    return out


def class_sigmas(
    rig: Rig, xy, mask, classes, *, estimator: str = "auto", pool: str = "frame", dist=None
) -> np.ndarray:
    """``(F,)`` σ̂ per frame (pixels), as :func:`associate_classes` estimates it with
    ``sigma="auto"``: from the epipolar nearest-neighbour distances within each class, the
    samples of all the frame's classes pooled (``pool="all"``: of all frames, one value
    repeated). ``estimator``: ``"auto"`` or ``"robust"`` (the ``sigma_mode`` whose fit is
    used, ALGORITHM.md §0.1). ``xy (F, M, P, 2)``, ``mask``, ``classes (F, M, P)`` and
    ``dist`` as in :func:`associate_classes`. A frame whose fit falls back (too few likely
    pairs, e.g. no class seen in two views: the fallback σ, ``FALLBACK_SIGMA_PX`` = 1 px; or
    σ̂ above 1 % of the focal length: that bound) is named in a ``UserWarning``, as
    :func:`associate_classes` flags it with ``Status.SIGMA_FALLBACK``."""
    expect_args("class_sigmas", rig=(rig, Rig))
    if estimator not in ("auto", "robust"):
        raise ValueError(f"class_sigmas: estimator must be 'auto' or 'robust'; got {estimator!r}")
    if pool not in ("frame", "all"):
        raise ValueError(f"class_sigmas: pool must be 'frame' or 'all'; got {pool!r}")
    xy, mask = np.asarray(as_array(xy)), np.asarray(as_array(mask))
    check_rig(rig)
    check_observations(xy, mask, rig.num_views, batched=True)
    classes = _check_classes(classes, mask)
    C = _num_classes(classes, mask, None, None)
    scenes = _regroup(xy, mask, classes, C, None)
    F = mask.shape[0]
    if len(scenes.frame) == 0:
        sigma, fell_back = np.full(F, FALLBACK_SIGMA_PX), np.ones(F, bool)
    else:
        dtype = jax.dtypes.canonicalize_dtype(
            xy.dtype if np.issubdtype(xy.dtype, np.floating) else np.float64
        )
        sigma, fell_back = _pooled_sigma(rig, scenes, F, dist, dtype, pool, estimator)
    if fell_back.any():
        frames = np.flatnonzero(fell_back)
        which = (
            "all frames pooled"
            if pool == "all"
            else f"{len(frames)} of {F} frames (first: frame {frames[0]})"
        )
        warnings.warn(
            f"class_sigmas: the σ fit of {which} fell back: too few likely pairs (σ = "
            f"{FALLBACK_SIGMA_PX:g} px) or σ̂ above 1 % of the focal length (σ = that bound)",
            stacklevel=2,
        )
    return sigma


def _check_classes(classes, mask: np.ndarray) -> np.ndarray:
    c = np.asarray(classes)
    if c.shape != mask.shape:
        raise ValueError(f"classes must have the shape of mask {mask.shape}; got {c.shape}")
    if not np.issubdtype(c.dtype, np.integer):
        raise ValueError(f"classes must be integer class ids; got dtype {c.dtype}")
    bad = mask & (c < 0)
    if bad.any():
        f, m, i = (int(v) for v in np.argwhere(bad)[0])
        raise ValueError(
            f"classes must be >= 0 where mask is True; got {int(c[f, m, i])} at frame {f}, view {m}, slot {i}"
        )
    return np.where(mask, c, 0).astype(np.int64)


def given_classes(names, num_classes, where: str = "") -> int | None:
    """The number of classes that ``class_names`` (a list of strings) and ``num_classes``
    (a positive int) state, checked against each other; ``None`` when neither is given.
    ``where`` starts the messages."""
    if names is not None:
        if isinstance(names, str) or not all(isinstance(n, str) for n in names):
            raise ValueError(f"{where}class_names must be a list of strings; got {names!r}")
        if num_classes is not None and num_classes != len(names):
            raise ValueError(
                f"{where}num_classes = {num_classes} but class_names has {len(names)} names"
            )
        num_classes = len(names)
    if num_classes is not None and (
        isinstance(num_classes, bool)
        or not isinstance(num_classes, (int, np.integer))
        or num_classes < 1
    ):
        raise ValueError(f"{where}num_classes must be a positive int; got {num_classes!r}")
    return num_classes


def _num_classes(classes: np.ndarray, mask: np.ndarray, names, num_classes) -> int:
    largest = int(classes[mask].max()) + 1 if mask.any() else 0
    num_classes = given_classes(names, num_classes)
    if num_classes is None:
        return max(largest, 1)
    if largest > num_classes:
        f, m, i = (int(v) for v in np.argwhere(mask & (classes >= num_classes))[0])
        raise ValueError(
            f"class id {int(classes[f, m, i])} at frame {f}, view {m}, slot {i} is >= num_classes = {num_classes}"
        )
    return int(num_classes)


def _regroup(xy, mask, classes, C, weights) -> _Scenes:
    """One scene per (frame, class) with detections in >= 2 views; slots by input order."""
    F, M, _ = mask.shape
    f, m, p = np.nonzero(mask)  # in (frame, view, slot) order
    key = f * C + classes[f, m, p]  # every detection's (frame, class) scene
    cell = key * M + m
    order = np.argsort(cell, kind="stable")  # by scene, then view; slots keep their order
    f, m, p, key, cell = f[order], m[order], p[order], key[order], cell[order]
    first = np.ones(len(cell), bool)  # the first detection of each (scene, view) cell
    first[1:] = cell[1:] != cell[:-1]
    start = np.flatnonzero(first)
    rank = np.arange(len(cell)) - start[np.cumsum(first) - 1]  # slot within its cell
    views = np.bincount(key[start], minlength=F * C)  # views that hold each scene
    live = np.flatnonzero(views >= 2)
    keep = views[key] >= 2
    b = (np.cumsum(views >= 2) - 1)[key[keep]]
    Pc = int(rank[keep].max()) + 1 if keep.any() else 1
    B = len(live)
    s_xy = np.zeros((B, M, Pc, 2), xy.dtype)
    s_mask = np.zeros((B, M, Pc), bool)
    slot = np.full((B, M, Pc), -1, np.int64)
    fk, mk, pk, rk = f[keep], m[keep], p[keep], rank[keep]
    s_xy[b, mk, rk] = xy[fk, mk, pk]
    s_mask[b, mk, rk] = True
    slot[b, mk, rk] = pk
    s_w = None
    if weights is not None:
        s_w = np.zeros((B, M, Pc), weights.dtype)
        s_w[b, mk, rk] = weights[fk, mk, pk]
    return _Scenes(s_xy, s_mask, slot, live // C, live % C, s_w)


_last_focal: tuple = ()


def _rig_focal(rig: Rig):
    """:func:`focal_scale` of ``rig.K`` on the host. A JAX ``K`` cannot change in place: the
    last one's value is kept, so that a frame loop on one rig reads it back and takes its
    median once (a NumPy ``K`` is read every time)."""
    global _last_focal
    K = rig.K
    if _last_focal and _last_focal[0] is K:
        return _last_focal[1]
    focal = focal_scale(np.asarray(K))
    if cannot_change(K):
        _last_focal = (K, focal)
    return focal


def _at_least(scenes: _Scenes, count: int, slots: int) -> _Scenes:
    """``scenes`` followed by empty ones up to ``count`` scenes (of the last scene's frame,
    so the scenes stay sorted by frame) and with empty slots up to the ladder rung that
    holds ``slots``: the σ samples and the association then meet the same compiled shapes
    whatever the frame holds. Empty scenes and slots carry no sample weight and hold no
    group."""
    B, _, Pc = scenes.mask.shape
    extra, wide = max(count - B, 0), slot_capacity(max(Pc, slots)) - Pc

    def pad(a, fill):  # (np.pad takes several times as long for these small tables)
        out = np.full((B + extra, a.shape[1], Pc + wide, *a.shape[3:]), fill, a.dtype)
        out[:B, :, :Pc] = a
        return out

    return _Scenes(
        pad(scenes.xy, 0),
        pad(scenes.mask, False),
        pad(scenes.slot, -1),
        np.concatenate([scenes.frame, np.full(extra, scenes.frame[-1])]),
        np.concatenate([scenes.cls, np.zeros(extra, scenes.cls.dtype)]),
        None if scenes.weights is None else pad(scenes.weights, 0),
    )


@partial(jit, static_argnames=("robust",))
def _nearest_samples(rig, xy, mask, dist, robust: bool):
    """The σ estimator's samples of every scene, each ``(B, M, Pc, M)``: a detection's
    epipolar distance to the nearest detection of its scene in every other view, its weight
    (0: none) and that view's count (``robust``: and the second-nearest distance), on
    undistorted pixels when ``dist`` is given."""

    def one(x, m):
        if dist is not None:
            x = undistorted(rig, x, m, dist)
        return (nearest_two_samples if robust else nearest_samples)(
            epipolar_distances(rig, x, m), m
        )

    return jax.vmap(one)(xy, mask)


SAMPLE_CHUNK = 4096
"""Scenes whose σ samples are computed in one call: a long recording's scenes go in chunks of
this many (the last padded with empty scenes), so that memory stays flat in its length."""


class _UsedSamples(NamedTuple):
    """The used entries (weight > 0) of every scene's σ samples, in scene order: what the σ
    fit reads, without the padding that most of a scene's sample table is."""

    values: list[np.ndarray]  # per array of :func:`_nearest_samples`: (K,) the used entries
    per_scene: np.ndarray  # (B,) used entries of each scene
    largest_count: np.ndarray  # (B,) each scene's largest view count (the fit reads it)


def _used(samples, B: int) -> _UsedSamples:
    """:class:`_UsedSamples` of the host arrays of :func:`_nearest_samples` for ``B`` scenes."""
    flat = [np.asarray(a).reshape(B, -1) for a in samples]
    used = flat[1] > 0
    return _UsedSamples([a[used] for a in flat], used.sum(axis=1), flat[2].max(axis=1))


def _chunked_samples(rig, scenes: _Scenes, dist, dtype, robust: bool) -> _UsedSamples:
    """The used entries of :func:`_nearest_samples` of every scene: in one call up to
    :data:`SAMPLE_CHUNK` scenes, else in chunks of that many (one program), each chunk cut to
    its used entries before the next is made (so a long recording holds only those)."""
    B = len(scenes.frame)
    xy, mask = scenes.xy, scenes.mask
    if B <= SAMPLE_CHUNK:
        return _used(
            call_stored(_nearest_samples, (rig, np.asarray(xy, dtype), mask, dist), robust=robust),
            B,
        )
    parts = []
    for start in range(0, B, SAMPLE_CHUNK):
        x, m = xy[start : start + SAMPLE_CHUNK], mask[start : start + SAMPLE_CHUNK]
        pad = SAMPLE_CHUNK - len(m)
        if pad:  # empty scenes: no sample
            x = np.concatenate([x, np.zeros((pad, *x.shape[1:]), x.dtype)])
            m = np.concatenate([m, np.zeros((pad, *m.shape[1:]), bool)])
        out = call_stored(_nearest_samples, (rig, np.asarray(x, dtype), m, dist), robust=robust)
        parts.append(_used([np.asarray(a)[: SAMPLE_CHUNK - pad] for a in out], SAMPLE_CHUNK - pad))
    return _UsedSamples(
        [np.concatenate(arrays) for arrays in zip(*(p.values for p in parts))],
        np.concatenate([p.per_scene for p in parts]),
        np.concatenate([p.largest_count for p in parts]),
    )


def _pooled_sigma(
    rig, scenes: _Scenes, F: int, dist, dtype, pool: str, estimator: str, min_samples: int = 0
) -> tuple[np.ndarray, np.ndarray]:
    """``(F,)`` σ per frame by the estimator of ``sigma_mode=estimator`` (``"auto"`` or
    ``"robust"``) on the nearest-distance samples of all the frame's class scenes
    (``pool="all"``: of all frames, one value), and ``(F,)`` whether it fell back (the
    estimator's ``fallback``: too little evidence, or σ̂ implausibly large); the fit's table
    at least ``min_samples`` wide."""
    d = None if dist is None else np.asarray(dist, dtype)
    robust = estimator == "robust"
    if _one_table(F, scenes, min_samples):
        # One frame: the samples, the table and the fit in one program (a live frame).
        sigma, fell_back = _one_table_fit(rig, scenes, d, dtype, robust, min_samples)
        return np.asarray(sigma)[:1], np.asarray(fell_back)[:1]
    samples = _chunked_samples(rig, scenes, d, dtype, robust)
    group = scenes.frame if pool == "frame" else np.zeros_like(scenes.frame)
    G = F if pool == "frame" else 1
    tables = _sample_tables(samples, group, G, min_samples)
    sigma, fell_back = _chunked_fit(
        _pooled_robust_fit if robust else _pooled_fit, tables, _rig_focal(rig)
    )
    if pool == "frame":
        return sigma, fell_back
    return np.full(F, sigma[0]), np.full(F, fell_back[0])


def _sample_bound(mask: np.ndarray) -> int:
    """An upper bound of the used σ samples of the scenes ``mask (B, M, P)``: a detection
    has a sample for each other view of its scene that holds a detection (none where the
    epipolar line is degenerate)."""
    per_view = mask.sum(axis=2)  # (B, M)
    other_views = (per_view > 0).sum(axis=1, keepdims=True) - (per_view > 0)
    return int((per_view * other_views).sum())


def _one_table(F: int, scenes: _Scenes, min_samples: int) -> bool:
    """Whether the σ of one frame's ``scenes`` is fitted by :func:`_one_table_fit`: a caller
    that gives the table's floor (a live frame) and scenes that one chunk of samples holds."""
    return bool(min_samples) and F == 1 and len(scenes.frame) <= SAMPLE_CHUNK


def _one_table_fit(rig, scenes: _Scenes, dist, dtype, robust: bool, min_width: int):
    """``(2,)`` σ and ``(2,)`` fallback (the first entries the frame's; JAX arrays, not read)
    of one frame's ``scenes`` pooled, as :func:`_chunked_samples`, :func:`_sample_tables`
    and :func:`_chunked_fit` give them for one group, bitwise, in one program
    (:func:`_pooled_table_fit`): no samples to the host and no table back. Its table is as
    wide as :func:`live_fit_width` of the samples' upper bound (:func:`_sample_bound`) + 1
    and ``min_width``, its sums as wide as :func:`fit_width` of it: σ is bitwise that of the
    power-of-two table the other fits use, at the narrower table's cost."""
    width = live_fit_width(_sample_bound(scenes.mask) + 1, min_width)
    args = (rig, np.asarray(scenes.xy, dtype), scenes.mask, dist, _rig_focal(rig), np.int32(1))
    return call_stored(_pooled_table_fit, args, robust=robust, width=width)


@partial(jit, static_argnames=("robust", "width"))
def _pooled_table_fit(rig, xy, mask, dist, focal, used, robust: bool, width: int):
    """:func:`_nearest_samples` of the scenes ``xy (B, M, P, 2)``, their used entries in
    scene order in one row of ``width`` entries (padding: weight 0, distance 0, count the
    scenes' largest; a second row empty, as :func:`_chunked_fit` gives one group) and
    :func:`_pooled_fit` (``robust``: :func:`_pooled_robust_fit`) of it: ``(2,)`` σ and
    ``(2,)`` fallback, the first row's first. ``used``: 1 (traced, as the fit's). The fit's
    sums are padded to :func:`fit_width` of ``width`` (:func:`~cdog_jax.graph._sigma.table_sum`):
    σ is that of the power-of-two table, bit for bit."""
    samples = [a.reshape(-1) for a in _nearest_samples.__wrapped__(rig, xy, mask, dist, robust)]
    taken = samples[1] > 0
    column = jnp.where(taken, jnp.cumsum(taken) - 1, width)  # width: dropped
    largest = jnp.maximum(jnp.max(samples[2]), 0)
    tables = []
    for k, a in enumerate(samples):
        row = jnp.full(width, largest if k == 2 else 0, a.dtype).at[column].set(a, mode="drop")
        tables.append(jnp.stack([row, jnp.zeros_like(row)]))
    fit_row = robust_sigma_from_samples if robust else sigma_from_samples
    return _row_by_row(partial(fit_row, sum_width=fit_width(width)), tuple(tables), focal, used)


def fit_width(samples: int) -> int:
    """The width of the σ fit's sums for ``samples`` entries: the power of two at or above it
    (at least 16). The table itself may be narrower (:func:`fine_fit_width`,
    :func:`live_fit_width`), its sums padded to this.

    Powers of two, not the finer shape ladder, so that σ does not depend on the width: XLA's
    CPU compiler sums more than 32 entries in windows of 32 and then sums the windows' sums
    the same way, padding a count of windows that is not a power of two on both sides. Between
    two powers of two the larger table's sums are the smaller's plus sums of zeros, bit for
    bit; a sum of 1,536 entries groups its windows otherwise, and σ differed from that at
    2,048 in the last bits (67 of 151 of Shelf's frames fitted alone)."""
    return 1 << max(4, (int(samples) - 1).bit_length())


def fine_fit_width(samples: int) -> int:
    """An offline σ fit's table width for ``samples`` entries (its fullest row's): one and a
    half times a power of two where that holds them, else :func:`fit_width`; its sums are
    padded to :func:`fit_width` (σ is bitwise the same), the fit's cost is per entry."""
    top = fit_width(samples)
    between = top // 2 * 3 // 2
    return between if top >= 32 and samples <= between else top


def live_fit_width(samples: int, floor: int) -> int:
    """One frame's σ fit table width (:func:`_one_table_fit`) for ``samples`` entries and a
    table of at least ``floor`` (a power of two, the first of :func:`sigma_fit_widths`):
    :func:`fit_width`, or one and a half times the floor where that holds the samples."""
    if floor < samples <= floor * 3 // 2:
        return floor * 3 // 2
    return fit_width(max(samples, floor))


def sigma_fit_widths(most: int) -> list[int]:
    """The σ fit's table widths of one frame whose used samples number at most ``most``:
    :func:`fit_width` of ``most`` (the fullest frame's), a half and a quarter of it, and one
    and a half times the quarter. A caller that must never compile after warming up (a live
    loop) warms these (:func:`warm_sigma_fits`) and gives the first as ``min_samples``:
    each frame's fit then runs on the narrowest that holds its samples
    (:func:`live_fit_width`), not on the fullest frame's (its cost is per entry; σ is
    bitwise the same). Most frames fill half the slots or less, their samples a quarter to
    a half of the fullest frame's: the widths in between pay there. Each width is a
    compiled fit (about 2 s on a 2-core CPU, and its code in memory)."""
    top = fit_width(most)
    floor = max(top // 4, 16)
    return sorted({w for w in (floor, floor * 3 // 2, top // 2, top) if floor <= w <= top})


def warm_sigma_fits(
    rig, widths, dtype, sigma_mode: str = "auto", *, scenes: int, slots: int, dist=None
) -> None:
    """Compile (or load) the σ fit of one frame of ``scenes`` class scenes of ``slots`` slots
    per view (the shapes :func:`associate_classes_at` gives them with ``min_scenes`` and
    ``min_slots``) for each table width in ``widths`` (:func:`sigma_fit_widths`), as it
    runs for ``sigma_mode`` (``"robust"``: the robust estimator) on ``dtype`` detections
    with ``dist`` (the given lens)."""
    M = rig.num_views
    xy = np.zeros((scenes, M, slots, 2), dtype)
    mask = np.zeros((scenes, M, slots), bool)
    d = None if dist is None else np.asarray(dist, dtype)
    for width in widths:
        args = (rig, xy, mask, d, _rig_focal(rig), np.int32(1))
        call_stored(_pooled_table_fit, args, robust=sigma_mode == "robust", width=width)


FIT_ELEMENTS = 1 << 16
"""Entries (rows × samples) of the σ fit's table in one call: a long recording's frames are
fitted in chunks of rows (the last padded with empty rows, which are not fitted), so that the
table on the device stays the same size whatever the recording's length, and one program
serves every chunk. Each row is fitted alone (:func:`_row_by_row`): its EM's temporaries are
one row's, and its σ is bitwise the same in any chunk and at any width that holds it."""


def _chunked_fit(fit, tables: list[np.ndarray], focal) -> tuple[np.ndarray, np.ndarray]:
    """``(G,)`` σ of every row of ``tables`` (``(G, S)`` each) by ``fit`` and ``(G,)``
    whether it fell back (``fit``'s two outputs), in chunks of rows of at most
    :data:`FIT_ELEMENTS` entries (a power of two rows), one program for all; with several
    devices, in at least one chunk per device (a ladder rung of rows), run side by side."""
    G, S = tables[0].shape
    rows = 1 << max(0, (FIT_ELEMENTS // S).bit_length() - 1)
    devices = len(jax.local_devices())
    if devices > 1 and G > 1:
        rows = min(rows, ladder_rung(-(-G // devices)))
    rows = max(rows, 2)
    if G <= rows:
        if G == 1:  # two rows (see _row_by_row), the second empty and not fitted
            tables = [np.concatenate([t, np.zeros_like(t)]) for t in tables]
        out = call_stored(fit, (*tables, focal, np.int32(G)))
        return tuple(np.asarray(a)[:G] for a in out)
    starts = range(0, G, rows)
    done, running = [], []
    for start, device in zip(starts, chunk_devices(len(starts))):
        if len(running) == devices:  # one chunk in flight per device: one's temporaries each
            done += [[np.asarray(a)[:n] for a in out] for out, n in running]
            running = []
        part = [t[start : start + rows] for t in tables]
        n = len(part[0])
        if n < rows:  # empty rows: weight 0, discarded
            part = [np.concatenate([t, np.zeros((rows - n, S), t.dtype)]) for t in part]
        args = (*part, focal, np.int32(n))
        args = args if device is None else jax.device_put(args, device)
        running.append((call_stored(fit, args), n))  # dispatched; the host waits above
    done += [[np.asarray(a)[:n] for a in out] for out, n in running]
    return np.concatenate([d[0] for d in done]), np.concatenate([d[1] for d in done])


def _sample_tables(samples: _UsedSamples, group: np.ndarray, G: int, min_width: int = 0) -> list:
    """The σ fit's inputs, ``(G, S)`` per array: each group's used samples side by side, in
    scene order, then padding of weight 0 up to :func:`fine_fit_width` of the largest
    group's count (+ 1) and ``min_width`` (the fit's sums padded to the power of two above:
    σ is bitwise the same at any width that holds the samples). ``samples``: the used entries
    of :func:`_nearest_samples` (distance, weight, count[, second distance]); ``group (B,)``
    each scene's group, sorted.

    Only the used samples enter the fit: a frame's table is mostly padding (empty slots, empty
    classes, a view against itself), and the EM's cost is per entry. The one number the fit
    reads from unused entries, the largest view count, is kept in every padding entry."""
    per_group = np.bincount(group, weights=samples.per_scene, minlength=G).astype(np.int64)
    # + 1: room for the largest count
    width = fine_fit_width(max(int(per_group.max()) + 1, min_width))
    rows = np.repeat(group, samples.per_scene)  # the group of each used sample, in order
    start = np.r_[0, np.cumsum(per_group)[:-1]]
    column = np.arange(len(rows)) - start[rows]
    largest = np.zeros(G, samples.largest_count.dtype)
    np.maximum.at(largest, group, samples.largest_count)
    tables = []
    for k, a in enumerate(
        samples.values
    ):  # padding: weight 0, distance 0; count the group's largest
        table = np.zeros((G, width), a.dtype)
        if k == 2:
            table[:] = largest[:, None]
        table[rows, column] = a
        tables.append(table)
    return tables


def _row_by_row(fit_row, tables: tuple, focal, used):
    """``(G,)`` σ and ``(G,)`` fallback of the first ``used`` rows of ``tables`` (``(G, S)``
    each; the rest 0 and False), one row at a time: a row's σ is then bitwise the same
    whatever the table's row count (a batch over the rows orders the sums by the rows'
    count), and the padding rows of a chunk cost nothing. Tables of one row are given two
    (:func:`_chunked_fit`): XLA compiles a row that is its table's only row otherwise."""
    G = tables[0].shape[0]

    def body(i, out):
        sigma, fallback = fit_row(*(t[i] for t in tables), focal)
        return out[0].at[i].set(sigma), out[1].at[i].set(fallback)

    init = (jnp.zeros(G, tables[0].dtype), jnp.zeros(G, bool))
    return jax.lax.fori_loop(0, used, body, init)


# Compiled once per table shape. Run eagerly, the fits' EM loops are traced and compiled
# again on every call (each call then leaves its programs' code mapped in memory, until
# the process runs out of memory maps), and the robust estimator's twelve fits take
# seconds more than compiling them.
# Called through call_stored: a later process loads the lowered fit instead of tracing it.
# The sums of a table's fit are padded to fit_width of its width (table_sum): bitwise the fit
# of the power-of-two table, at the narrower table's cost.
@jit
def _pooled_fit(x, w, count, focal, used):
    fit = partial(sigma_from_samples, sum_width=fit_width(x.shape[-1]))
    return _row_by_row(fit, (x, w, count), focal, used)


@jit
def _pooled_robust_fit(x, w, count, second, focal, used):
    fit = partial(robust_sigma_from_samples, sum_width=fit_width(x.shape[-1]))
    return _row_by_row(fit, (x, w, count, second), focal, used)


def _map_back(
    r, scenes: _Scenes, F, M, P, C, names, on_host: bool = False, frame_flags=None
) -> ClassAssociation:
    """Scene results ``(B, …)`` as one table of groups per frame, in the input's slots;
    ``frame_flags (F,)``: status bits of each frame beyond its scenes' (set where the frame
    has a scene)."""
    b, g = np.nonzero(r.valid)
    f, c = scenes.frame[b], scenes.cls[b]
    order = np.lexsort((g, c, f))
    b, g, f, c = b[order], g[order], f[order], c[order]
    count = np.bincount(f, minlength=F)
    row = np.arange(len(f)) - np.repeat(np.cumsum(count) - count, count)
    G = max(1, int(count.max()) if len(count) else 1)
    slots = r.groups[b, g]  # (K, M) scene slots
    views = np.arange(M)[None, :]
    orig = np.where(slots >= 0, scenes.slot[b[:, None], views, np.maximum(slots, 0)], -1)
    groups = np.full((F, G, M), -1, np.int32)
    groups[f, row] = orig
    valid = np.zeros((F, G), bool)
    valid[f, row] = True
    labels = np.full((F, M, P), -1, np.int32)
    k, mm = np.nonzero(orig >= 0)
    labels[f[k], mm, orig[k, mm]] = row[k]
    group_class = np.full((F, G), -1, np.int32)
    group_class[f, row] = c

    def place(a, fill=0):
        out = np.full((F, G, *a.shape[2:]), fill, a.dtype)
        out[f, row] = a[b, g]
        return out

    sigma, tau, status = frame_fields(r, scenes.frame, F, frame_flags)
    assoc = batched_association(
        on_host=on_host,
        labels=labels,
        groups=groups,
        valid=valid,
        points3d=place(r.points3d),
        bpe=place(r.bpe),
        err_px=place(r.err_px),
        n_views=place(r.n_views),
        num_groups=count.astype(np.int32),
        sigma_px=sigma,
        tau_px=tau,
        status=status,
    )
    return ClassAssociation(assoc, group_class, None if names is None else tuple(names), C)


def frame_fields(
    r, frame: np.ndarray, F: int, frame_flags: np.ndarray | None
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(F,)`` σ, τ and status of every frame from its scenes' (``r``'s fields ``(B,)``,
    ``frame (B,)`` each scene's frame, sorted): the median σ and τ over its scenes, its
    scenes' flags and the frame's own ``frame_flags`` (set where it has a scene)."""
    status = np.zeros(F, np.int32)
    np.bitwise_or.at(status, frame, np.asarray(r.status).astype(np.int32))
    if frame_flags is not None:
        status |= np.where(np.bincount(frame, minlength=F) > 0, frame_flags, 0)
    sigma = _per_frame(np.asarray(r.sigma_px), frame, F)
    tau = _per_frame(np.asarray(r.tau_px), frame, F)
    return sigma, tau, status


def frame_of_scenes(
    result: Association,
    slot: Int[Array, "B M Pc"],
    scene_class: Int[Array, " B"],
    num_slots: int,
    rows: int,
    table_rows: int,
) -> tuple:
    """One frame's table from its class scenes' results ``(B, G, …)``, traced: what
    :func:`_map_back` and ``tracking_frames`` make on the host, for a program that hands
    it on. ``slot (B, M, Pc)``: the frame slot of every scene slot (-1: none); the frame has
    ``num_slots`` slots per view. Returns ``(X (H, 3), valid (H,), cls (H,), groups (H, M),
    bpe (H,), err_px (H,), labels (M, num_slots), found, tau)``: the frame's groups in scene
    order (the scenes are sorted by class), the first ``rows`` of them in ``H = table_rows``
    rows, the labels of all of them, how many there are and the median τ of the scenes."""
    B, G, M = result.groups.shape
    valid = result.valid.reshape(B * G)
    row = jnp.cumsum(valid, dtype=jnp.int32) - 1  # each valid group's row in the frame
    scene = jnp.repeat(jnp.arange(B, dtype=jnp.int32), G)
    views = jnp.arange(M, dtype=jnp.int32)
    in_scene = result.groups.reshape(B * G, M)
    groups = jnp.where(
        valid[:, None] & (in_scene >= 0),
        slot[scene[:, None], views[None, :], jnp.maximum(in_scene, 0)],
        -1,
    )
    at = jnp.where(valid & (row < rows), row, table_rows)  # past the table: dropped

    def place(a, fill):
        a = a.reshape(B * G, *a.shape[2:])
        return jnp.full((table_rows, *a.shape[1:]), fill, a.dtype).at[at].set(a, mode="drop")

    flat = jnp.where(groups >= 0, views[None, :] * num_slots + groups, M * num_slots)
    labels = (
        jnp.full((M * num_slots,), -1, jnp.int32)
        .at[flat.reshape(-1)]
        .set(jnp.repeat(row, M), mode="drop")
        .reshape(M, num_slots)
    )
    tau = jnp.sort(result.tau_px)  # the median as NumPy takes it
    tau = tau[B // 2] if B % 2 else (tau[B // 2 - 1] + tau[B // 2]) / 2
    return (
        place(result.points3d, 0),
        place(result.valid, False),
        place(jnp.broadcast_to(scene_class[:, None], (B, G)).astype(jnp.int32), -1),
        jnp.full((table_rows, M), -1, jnp.int32).at[at].set(groups, mode="drop"),
        place(result.bpe, 0),
        place(result.err_px, 0),
        labels,
        jnp.sum(valid, dtype=jnp.int32),
        tau,
    )


@partial(jit, static_argnames=("num_slots", "rows"))
def _frame_table(result, slot, scene_class, *, num_slots: int, rows: int) -> tuple:
    """:func:`frame_of_scenes` in ``rows`` rows, its fields the person vote reads: ``(X,
    valid, cls, groups, bpe, err_px, found)``."""
    X, valid, cls, groups, bpe, err_px, _, found, _ = frame_of_scenes(
        result, slot, scene_class, num_slots, rows, rows
    )
    return X, valid, cls, groups, bpe, err_px, found


class _Voted(NamedTuple):
    """The fields of one frame's association that :func:`person_consistent` reads."""

    groups: np.ndarray
    valid: np.ndarray
    points3d: np.ndarray
    bpe: np.ndarray
    err_px: np.ndarray
    tau_px: np.ndarray


def vote_on_scenes(
    rig: Rig,
    scenes: SceneResults,
    xy: np.ndarray,
    mask: np.ndarray,
    classes: np.ndarray,
    instances: np.ndarray,
    vote,
    *,
    rows: int,
    num_classes: int,
    dist=None,
    min_views: int = 2,
) -> ClassAssociation | None:
    """One frame's class scenes (:func:`associate_classes_at` with ``scenes_only``) as the
    frame's groups after the person vote: the same arrays as :func:`associate_classes_at`
    with ``instances``, ``person_vote`` and ``on_host`` (``min_vote_rows=rows``). The
    frame's table is made from the scenes' tables on the device (one small program), so
    that only the frame's groups come to the host, not every scene's table. ``xy``,
    ``mask``, ``classes``, ``instances``: the frame ``(1, M, P)``, checked. ``None`` when
    the frame holds more than ``rows`` groups (the table has no room for them)."""
    sc = scenes.scenes
    table = _frame_table(
        scenes.result,
        sc.slot.astype(np.int32),
        sc.cls.astype(np.int32),
        num_slots=mask.shape[-1],
        rows=rows,
    )
    X, valid, cls, groups, bpe, err_px, found = jax.device_get(table)
    if found > rows:
        return None
    G = max(1, int(found))  # as _map_back: a frame may hold no group
    sigma, tau, status = frame_fields(scenes.result, sc.frame, 1, scenes.flags())
    before = _Voted(
        groups[None, :G], valid[None, :G], X[None, :G], bpe[None, :G], err_px[None, :G], tau
    )
    fixed = person_consistent(
        rig,
        before,
        cls[None, :G],
        xy,
        mask,
        classes,
        check_instances(instances, mask),
        vote,
        dist=dist,
        min_views=min_views,
        min_rows=rows,
    )
    assoc = batched_association(
        on_host=True,
        **{k: v for k, v in fixed._asdict().items() if k != "group_class"},
        sigma_px=sigma,
        tau_px=tau,
        status=status,
    )
    return ClassAssociation(assoc, fixed.group_class, None, num_classes)


def _per_frame(values: np.ndarray, frame: np.ndarray, F: int) -> np.ndarray:
    """The median over each frame's scenes (one value when σ was pooled); 0 without scenes."""
    out = np.zeros(F, values.dtype)
    start = np.r_[0, np.flatnonzero(np.diff(frame)) + 1]  # scenes are sorted by frame
    for lo, hi in zip(start, np.r_[start[1:], len(frame)]):
        scenes = values[lo:hi]
        # σ pooled over a frame is one value in all its scenes: no median to take (np.median
        # costs about 20 µs a call, ten times the comparison; a live frame makes two).
        out[frame[lo]] = scenes[0] if (scenes == scenes[0]).all() else np.median(scenes)
    return out


def _empty(rig, F, M, P, dtype, C, names, on_host: bool = False) -> ClassAssociation:
    dtype = dtype if np.issubdtype(dtype, np.floating) else np.float64
    z = lambda *shape, dt=dtype: np.zeros(shape, dt)  # noqa: E731
    assoc = batched_association(
        on_host=on_host,
        labels=np.full((F, M, P), -1, np.int32),
        groups=np.full((F, 1, M), -1, np.int32),
        valid=np.zeros((F, 1), bool),
        points3d=z(F, 1, 3),
        bpe=z(F, 1),
        err_px=z(F, 1),
        n_views=z(F, 1, dt=np.int32),
        num_groups=z(F, dt=np.int32),
        sigma_px=z(F),
        tau_px=z(F),
        status=z(F, dt=np.int32),
    )
    return ClassAssociation(
        assoc, np.full((F, 1), -1, np.int32), None if names is None else tuple(names), C
    )
