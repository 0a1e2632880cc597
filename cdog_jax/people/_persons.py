"""Person-level consistency of classed groups (ALGORITHM.md §15.1; beyond the paper).

When every detection carries a per-view instance index (the 2D skeleton it belongs to in
its view, as a pose estimator outputs it: OpenPose's person index), the joint groups of a
frame vote on which (view, instance) pairs are one 3D person; the (view, instance) nodes
are clustered into people under view-uniqueness, and every joint detection whose group
belongs to another person (one that shares a view with its own) is detached and
re-attached to its person's group of that class when it reprojects within the gate.

This is a host step in plain NumPy (not jitted; a frame holds a few dozen nodes), run by
:func:`cdog_jax.associate_classes` after the compiled association; only the
re-triangulation of the groups it changes is compiled (:func:`_retriangulate`).
"""

from __future__ import annotations

import dataclasses
import heapq
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from .._runtime.xla_kernels import jit
from ..geometry._camera import Rig, cannot_change
from ..geometry._distortion import as_lens, undistorted_frames
from ..geometry._projection import group_errors
from ..geometry._triangulate import triangulate_views_last


@dataclasses.dataclass(frozen=True)
class PersonVote:
    """The numbers of the person-level vote (``associate_classes(..., person_vote=)``).

    Attributes:
        min_votes: joint groups that must link two clusters of (view, instance) nodes, on
            average over their node pairs, for them to merge into one person.
        gate: a detached joint is re-attached to its person's group of its class when its
            distance to that group's 3D point projected into its view is at most
            ``gate · τ`` (τ: the frame's epipolar gate ``tau_px``, pixels).
    """

    min_votes: int | float = 2.0
    gate: int | float = 2.0

    def __post_init__(self):
        if (
            isinstance(self.min_votes, bool)
            or not isinstance(self.min_votes, (int, float))
            or not self.min_votes > 0
        ):
            raise ValueError(f"PersonVote.min_votes must be a number > 0; got {self.min_votes!r}")
        if (
            isinstance(self.gate, bool)
            or not isinstance(self.gate, (int, float))
            or not self.gate > 0
        ):
            raise ValueError(f"PersonVote.gate must be a number > 0; got {self.gate!r}")


def person_vote_argument(person_vote, instances) -> PersonVote | None:
    """``person_vote`` (``None``: on when ``instances`` is given, ``False``: off, ``True``:
    the defaults, or a :class:`PersonVote`) as a :class:`PersonVote` or ``None`` (off);
    on, it needs ``instances``."""
    if person_vote is None:
        person_vote = instances is not None
    if person_vote is False:
        return None
    vote = PersonVote() if person_vote is True else person_vote
    if not isinstance(vote, PersonVote):
        raise ValueError(f"person_vote must be a bool or a PersonVote; got {person_vote!r}")
    if instances is None:
        raise ValueError(
            "person_vote needs instances= (the per-view instance index of every detection)"
        )
    return vote


def check_instances(instances, mask: np.ndarray) -> np.ndarray:
    """``instances (F, M, P)`` as int64 with -1 where ``mask`` is False. Raises ``ValueError``
    naming the frame, view and slot for a wrong shape, a non-integer dtype or an index below -1."""
    a = np.asarray(instances)
    if a.shape != mask.shape:
        raise ValueError(f"instances must have the shape of mask {mask.shape}; got {a.shape}")
    if a.dtype == bool or not np.issubdtype(a.dtype, np.integer):
        raise ValueError(
            f"instances must be integer instance indices (-1: unknown); got dtype {a.dtype}"
        )
    bad = mask & (a < -1)
    if bad.any():
        f, m, i = (int(v) for v in np.argwhere(bad)[0])
        raise ValueError(
            f"instances must be >= -1 (-1: unknown); got {int(a[f, m, i])} at frame {f}, view {m}, slot {i}"
        )
    return np.where(mask, a, -1).astype(np.int64)


# ------------------------------------------------------------------ the vote (one frame)


def person_nodes(instances: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The (view, instance) nodes of one frame: ``node (M, P)`` id of every slot's node
    (-1 where the instance is unknown) and ``node_view (N,)``; ids in (view, instance) order."""
    M = instances.shape[0]
    known = instances >= 0
    view = np.broadcast_to(np.arange(M)[:, None], instances.shape)
    # One integer per (view, instance), in their order: np.unique of rows sorts far slower.
    span = int(instances.max()) + 1 if known.any() else 1
    keys, inverse = np.unique(
        view[known].astype(np.int64) * span + instances[known], return_inverse=True
    )
    node = np.full(instances.shape, -1, np.int64)
    node[known] = inverse.reshape(-1)
    return node, keys // span


def vote_matrix(groups: np.ndarray, valid: np.ndarray, node: np.ndarray) -> np.ndarray:
    """``(N, N)`` int votes between nodes (``node (M, P)``, :func:`person_nodes`): how many
    valid groups ``groups (G, M)`` (slots, -1) hold a detection of both."""
    N = int(node.max()) + 1 if node.size else 0
    return _votes(_held_nodes(groups, valid, node, N)[1])


def _held_nodes(
    groups: np.ndarray, valid: np.ndarray, node: np.ndarray, N: int
) -> tuple[np.ndarray, np.ndarray]:
    """``member (G, M)``: the node of every valid group's member in each view (``N``: none,
    or of unknown instance), and ``holds (G, N)`` int64, 1 where the group holds a detection
    of the node."""
    G, M = groups.shape
    at = node[np.arange(M)[None, :], np.maximum(groups, 0)]
    member = np.where((groups >= 0) & valid[:, None] & (at >= 0), at, N)
    holds = np.zeros((G, N + 1), np.int64)
    holds[np.arange(G)[:, None], member] = 1
    return member, holds[:, :N]


def _votes(holds: np.ndarray) -> np.ndarray:
    """``(N, N)`` votes of the groups' ``holds (G, N)`` (:func:`_held_nodes`): the groups
    holding both nodes. Two nodes of one view are never in one group, so the product counts
    pairs of views, as the votes do; a node with itself is no vote."""
    votes = holds.T @ holds
    np.fill_diagonal(votes, 0)
    return votes


def cluster_people(votes: np.ndarray, node_view: np.ndarray, min_votes: int | float) -> np.ndarray:
    """``(N,)`` person of every node (the id of its cluster's first node): greedy average
    linkage, each step merging the two clusters with the most votes per node pair between
    them among those that share no view (``node_view (N,)``), while that mean is at least
    ``min_votes``. (A sum over the pairs would let a few stray votes from each node of a
    large cluster add up to a merge.) Ties go to the pair ``(a, b)``, ``a < b``, first in
    row-major order; ``b`` merges into ``a``. ``votes (N, N)``: symmetric counts
    (:func:`vote_matrix`).

    The allowed merges wait in a heap, best mean first: a merge of ``b`` into ``a`` changes
    only the pairs of ``a`` (pushed again with their new means) and ends those of ``b``, so
    an entry whose clusters changed since it was pushed is dropped when it comes up. A
    frame holds a few dozen nodes: plain Python on them costs less than a NumPy call per
    step. Votes are counts, so the sums are exact and every mean is one division, the same
    bits whatever the order of the merges before it."""
    N = votes.shape[0]
    W = votes.tolist()  # (N, N) votes between clusters (rows and columns of live ones)
    size = [1] * N
    views = [1 << v for v in node_view.tolist()]  # each cluster's views as the bits of an int
    version = [0] * N  # -1: merged into another
    members = [[n] for n in range(N)]
    heap = [
        (-mean, a, b, 0, 0)
        for a in range(N)
        for b in range(a + 1, N)
        if not views[a] & views[b] and (mean := W[a][b] / 1) >= min_votes
    ]
    heapq.heapify(heap)
    alive = list(range(N))  # the clusters not merged into another, in order
    while heap:
        _, a, b, version_a, version_b = heapq.heappop(heap)
        if version_a != version[a] or version_b != version[b]:
            continue  # a or b has merged since this entry was pushed
        version[a] += 1
        version[b] = -1
        alive.remove(b)
        members[a] += members[b]
        views[a] |= views[b]
        size[a] += size[b]
        W_a, W_b, views_a, size_a = W[a], W[b], views[a], size[a]
        for j in alive:
            if j == a:
                continue
            w = W_a[j] + W_b[j]  # the votes stay symmetric: one sum for both entries
            W_a[j] = W[j][a] = w
            if not views_a & views[j]:
                mean = w / (size_a * size[j])
                if mean >= min_votes:
                    i, k = (a, j) if a < j else (j, a)
                    heapq.heappush(heap, (-mean, i, k, version[i], version[k]))
    label = np.arange(N)
    for root in alive:
        label[members[root]] = root
    return label


class FramePeople(NamedTuple):
    """One frame's people: ``det_person (M, P)`` person of every detection (-1: instance
    unknown), ``group_person (G,)`` person of every group (the most frequent among its
    members; -1 when none is known) and ``foreign (G, M)`` members of another person than
    their group's, where the two people share a view (two people seen in one view cannot be
    one; two that share no view may be one person with too few votes to merge, so such a
    member is no evidence against its group). Persons are labelled by their first node."""

    det_person: np.ndarray
    group_person: np.ndarray
    foreign: np.ndarray


def frame_people(
    groups: np.ndarray, valid: np.ndarray, instances: np.ndarray, min_votes: int | float
) -> FramePeople | None:
    """The people of one frame's groups ``groups (G, M)``, ``valid (G,)``, from the per-view
    ``instances (M, P)`` (:func:`person_nodes`, :func:`vote_matrix`, :func:`cluster_people`);
    ``None`` when no instance is known."""
    M = groups.shape[1]
    node, node_view = person_nodes(instances)
    N = len(node_view)
    if N == 0:
        return None
    member, holds = _held_nodes(groups, valid, node, N)
    person = cluster_people(_votes(holds), node_view, min_votes)
    det_person = np.where(node >= 0, person[np.maximum(node, 0)], -1)  # (M, P)
    member_person = np.r_[person, -1][member]  # (G, M)
    # Each group's person: the most frequent among its members (ties: the smallest id; -1
    # when none is known), from its members counted per person (a frame may hold no group).
    per_person = holds @ (person[:, None] == np.arange(N)[None, :])  # (G, N)
    group_person = np.where(per_person.any(axis=1), np.argmax(per_person, axis=1), -1)
    person_views = np.zeros((N, M), np.int64)
    person_views[person, node_view] = 1
    share_a_view = (person_views @ person_views.T) > 0  # (N, N) between persons
    clash = share_a_view[np.maximum(member_person, 0), np.maximum(group_person, 0)[:, None]]
    foreign = (member_person >= 0) & (member_person != group_person[:, None]) & clash
    return FramePeople(det_person, group_person, foreign)


class FrameGroups(NamedTuple):
    """A frame's groups after the vote: ``groups (G', M)``, ``valid (G',)``, ``group_class
    (G',)``, ``changed (G',)`` (members changed or new: to re-triangulate) and ``source
    (G',)`` (the input group a kept group was, -1 for a new one)."""

    groups: np.ndarray
    valid: np.ndarray
    group_class: np.ndarray
    changed: np.ndarray
    source: np.ndarray


def consistent_groups(
    groups,
    valid,
    group_class,
    classes,
    instances,
    xy,
    points3d,
    project,
    gate_px: float,
    vote: PersonVote,
    min_views: int,
) -> FrameGroups:
    """One frame's groups made consistent with the per-view instances.

    Args:
        groups: ``(G, M)`` slot of each valid group's member per view, -1.
        valid: ``(G,)``; group_class: ``(G,)`` class of each group.
        classes, instances: ``(M, P)`` class and per-view instance (-1 unknown) of every slot.
        xy: ``(M, P, 2)`` pinhole pixels; points3d: ``(G, 3)`` the groups' points.
        project: ``X (K, 3) -> (K, M, 2)`` pinhole pixels in every view, with
            ``project.triangulate(xy, rows (K, M)) -> (K, 3)`` the DLT of groups.
        gate_px: the re-attachment gate (pixels).
        vote: the numbers; min_views: a group keeps at least this many views.

    Steps: (1) (view, instance) nodes clustered into people (:func:`person_nodes`,
    :func:`vote_matrix`, :func:`cluster_people`);
    (2) each group's person is the most frequent person of its members; members of another
    person that shares a view with it are detached, and a group left with fewer than ``min_views`` members is
    dissolved (its members detached); (3) each detached joint (in group, then view order)
    joins the largest group of its class and person with no member in its view, when it
    lies within ``gate_px`` of that group's point projected into its view (the point
    re-triangulated without the detached members first); (4) the joints still detached,
    one per view (the first) for each (class, person), form a new group when they span at
    least ``min_views`` views and all reproject within ``gate_px`` of their own DLT point.
    Detections of unknown instance are never moved.
    """
    M = groups.shape[1]
    groups = np.where(valid[:, None], groups, -1)
    people = frame_people(groups, valid, instances, vote.min_votes)
    if people is None:  # no instance known: nothing to vote on
        return FrameGroups(
            groups, valid, group_class, np.zeros(len(valid), bool), np.arange(len(valid))
        )
    det_person, group_person, detach = people.det_person, people.group_person, people.foreign
    kept = np.where(detach, -1, groups)
    small = valid & ((kept >= 0).sum(axis=1) < min_views) & detach.any(axis=1)
    detach |= (
        small[:, None] & (kept >= 0) & (det_person[np.arange(M)[None, :], np.maximum(kept, 0)] >= 0)
    )
    kept = np.where(detach, -1, kept)
    small = valid & ((kept >= 0).sum(axis=1) < min_views)
    valid = valid & ~small
    kept = np.where(valid[:, None], kept, -1)
    changed = detach.any(axis=1) & valid
    if not detach.any():
        return FrameGroups(groups, valid, group_class, changed, np.arange(len(valid)))
    g_idx, m_idx = np.nonzero(detach)
    slots = groups[g_idx, m_idx]
    # A changed group's point is re-triangulated only where a detached joint may join it:
    # a group of the joint's class and person with no member in the joint's view before the
    # loop (the loop only fills views, so its choices are among these). Frames that need
    # none skip the DLT's call; a point's DLT is the same bits alone or among others.
    may_join = (
        valid[None, :]
        & (group_class[None, :] == classes[m_idx, slots][:, None])
        & (group_person[None, :] == det_person[m_idx, slots][:, None])
        & (kept[:, m_idx].T < 0)
    ).any(axis=0)  # (G,)
    points = points3d.copy()
    if (needed := changed & may_join).any():
        points[needed] = project.triangulate(xy, kept[needed])

    # (3) re-attach to the person's group of the class. The points stay as they are through
    # the loop, so they are projected once (a point's pixels are the same bits alone or
    # among others).
    pixels = np.zeros((len(valid), M, 2))  # (G, M, 2) of the valid groups' points
    with np.errstate(invalid="ignore", over="ignore"):  # a point at infinity meets no gate
        pixels[valid] = project(points[valid])
    left = []
    for m, s in zip(m_idx.tolist(), slots.tolist()):
        c, p = classes[m, s], det_person[m, s]
        options = np.flatnonzero(
            valid & (group_class == c) & (group_person == p) & (kept[:, m] < 0)
        )
        if options.size:
            g = options[np.argmax((kept[options] >= 0).sum(axis=1))]
            if np.linalg.norm(pixels[g, m] - xy[m, s]) <= gate_px:
                kept[g, m] = s
                changed[g] = True
                continue
        left.append((int(c), int(p), m, s))

    # (4) what is left forms groups of its own.
    new = []
    for c, p in dict.fromkeys((c, p) for c, p, _, _ in left):
        row = np.full(M, -1, np.int64)
        for c2, p2, m, s in left:
            if (c2, p2) == (c, p) and row[m] < 0:
                row[m] = s
        if (row >= 0).sum() < max(min_views, 2):
            continue
        X = project.triangulate(xy, row[None])
        views = np.flatnonzero(row >= 0)
        err = np.linalg.norm(project(X)[0, views] - xy[views, row[views]], axis=-1)
        if np.all(err <= gate_px):
            new.append((row, c))
    if new:
        kept = np.concatenate([kept, np.stack([r for r, _ in new])])
        valid = np.r_[valid, np.ones(len(new), bool)]
        group_class = np.r_[group_class, np.array([c for _, c in new], group_class.dtype)]
        changed = np.r_[changed, np.ones(len(new), bool)]
    source = np.r_[np.arange(len(groups)), np.full(len(new), -1)]
    return FrameGroups(kept.astype(np.int32), valid, group_class, changed, source)


# ------------------------------------------------------------------ all frames


class _Camera:
    """Projection and DLT on pinhole pixels of one rig (host side; DLT compiled once per
    padded group count: a power of two, at least ``min_rows``)."""

    def __init__(self, rig: Rig, min_rows: int = 8):
        self.rig = rig
        self.P = rig.host_proj()  # (M, 3, 4), float64
        self.min_rows = min_rows

    def __call__(self, X: np.ndarray) -> np.ndarray:
        h = (
            np.einsum("mij,kj->kmi", self.P[:, :, :3], np.asarray(X, np.float64))
            + self.P[None, :, :, 3]
        )
        return h[..., :2] / np.where(np.abs(h[..., 2:]) > 0, h[..., 2:], np.inf)

    def triangulate(
        self, xy: np.ndarray, rows: np.ndarray, weights: np.ndarray | None = None
    ) -> np.ndarray:
        X, _, _, _ = self.solve(xy, rows, weights)
        return X

    def solve(self, xy, rows, weights=None):
        """Points, ok, BPE (px²), mean error (px) of groups ``rows (K, M)`` on ``xy (M, P, 2)``
        (DLT weighted by ``weights (M, P)`` when given, as the pipeline's final points)."""
        K, M = rows.shape
        pad = retriangulation_rows(max(K, self.min_rows))
        table = np.full((pad, M), -1, np.int64)
        table[:K] = rows
        member = table >= 0
        at = (np.arange(M)[None, :], np.maximum(table, 0))
        xy_g = np.where(member[..., None], xy[at], 0.0)
        w = np.where(member, 1.0 if weights is None else weights[at], 0.0)
        dtype = np.dtype(self.rig.K.dtype)
        # Host arrays straight into the compiled program: one eager jnp.asarray each would
        # cost more than the program itself (three per call, two calls a frame).
        out = _retriangulate(self.rig, xy_g.astype(dtype), member, w.astype(dtype))
        return tuple(np.asarray(a)[:K] for a in out)


_LAST_CAMERA: list[_Camera] = []  # the last rig's: a live loop passes one rig every frame


def _camera(rig: Rig, min_rows: int) -> _Camera:
    """:class:`_Camera` of ``rig``, the last one made when ``rig`` is the same object with
    JAX cameras (its projection matrices computed once, not every frame). A JAX array cannot
    change in place; a NumPy one can, so a rig of NumPy cameras is read every call."""
    camera = _LAST_CAMERA[0] if _LAST_CAMERA else None
    if camera is not None and camera.rig is rig and camera.min_rows == min_rows:
        return camera
    camera = _Camera(rig, min_rows)
    if cannot_change(rig.K, rig.R, rig.t):
        _LAST_CAMERA[:] = [camera]
    return camera


@jit
def _retriangulate(rig, xy_g, member, weights):
    X, ok = triangulate_views_last(rig, xy_g, member, weights=weights)
    bpe, err = group_errors(rig, X, xy_g, member)
    return X, ok, bpe, err


def retriangulation_rows(groups: int) -> int:
    """The rows of the vote's DLT table for ``groups`` groups: the power of two that holds
    them, at least 8 (few programs; a row costs little beside the call)."""
    return max(8, 1 << (max(groups, 1) - 1).bit_length())


def warm_retriangulation(rig: Rig, groups: int) -> None:
    """Compile (or load) the vote's DLT for tables of ``groups`` rows
    (:func:`retriangulation_rows`), as :func:`person_consistent` with ``min_rows=groups``
    runs it: a live loop then compiles nothing when a later frame first changes a group."""
    rows, M = retriangulation_rows(groups), rig.num_views
    dtype = np.dtype(rig.K.dtype)
    zeros = np.zeros((rows, M), dtype)
    jax.block_until_ready(_retriangulate(rig, np.zeros((rows, M, 2), dtype), zeros > 0, zeros))


class PersonGroups(NamedTuple):
    """Every frame's groups after the vote, padded to ``G'``: the fields of a batched
    :class:`cdog_jax.Association` that change, and ``group_class (F, G')``."""

    labels: np.ndarray
    groups: np.ndarray
    valid: np.ndarray
    points3d: np.ndarray
    bpe: np.ndarray
    err_px: np.ndarray
    n_views: np.ndarray
    num_groups: np.ndarray
    group_class: np.ndarray


def person_consistent(
    rig: Rig,
    assoc,
    group_class,
    xy,
    mask,
    classes,
    instances,
    vote: PersonVote,
    *,
    dist=None,
    weights=None,
    min_views: int = 2,
    min_rows: int = 8,
) -> PersonGroups:
    """The groups of a batched association ``assoc`` (``(F, …)``, as
    :func:`cdog_jax.associate_classes` builds it, with ``group_class (F, G)``) made
    consistent with ``instances (F, M, P)`` frame by frame (:func:`consistent_groups`, gate
    ``vote.gate · tau_px`` of the frame). ``xy (F, M, P, 2)`` as detected (undistorted with
    ``dist`` first), ``mask``, ``classes (F, M, P)``; ``weights (F, M, P)`` weight the DLT
    of the changed groups. Valid groups come first, by class, kept groups in their order,
    new ones after them. The DLT of changed groups runs on tables of at least ``min_rows``
    rows (:func:`retriangulation_rows`; a live loop gives its group capacity: one program)."""
    F, M, P = mask.shape
    dtype = np.asarray(assoc.points3d).dtype
    pinhole = np.asarray(xy, np.float64)
    if dist is not None:
        lens, xy_j = as_lens(dist, rig.K.dtype), jnp.asarray(xy, rig.K.dtype)
        pinhole = np.asarray(undistorted_frames(rig, xy_j, jnp.asarray(mask), lens), np.float64)
    camera = _camera(rig, min_rows)
    fields = {
        k: np.asarray(getattr(assoc, k)) for k in ("groups", "valid", "points3d", "bpe", "err_px")
    }
    tau = np.asarray(assoc.tau_px)
    frames = []
    for f in range(F):
        fg = consistent_groups(
            fields["groups"][f],
            fields["valid"][f],
            np.asarray(group_class[f]),
            classes[f],
            instances[f],
            pinhole[f],
            fields["points3d"][f],
            camera,
            vote.gate * float(tau[f]),
            vote,
            min_views,
        )
        points = np.zeros((len(fg.valid), 3))
        bpe, err = np.zeros(len(fg.valid)), np.zeros(len(fg.valid))
        old = fg.source >= 0
        for name, a in (("points3d", points), ("bpe", bpe), ("err_px", err)):
            a[old] = fields[name][f][fg.source[old]]
        redo = fg.changed & fg.valid
        valid = fg.valid.copy()
        if redo.any():
            X, ok, b, e = camera.solve(
                pinhole[f], fg.groups[redo], None if weights is None else weights[f]
            )
            points[redo], bpe[redo], err[redo] = X, b, e
            valid[np.flatnonzero(redo)[~ok]] = False
        order = np.flatnonzero(valid)
        order = order[np.argsort(fg.group_class[order], kind="stable")]
        frames.append(
            (fg.groups[order], fg.group_class[order], points[order], bpe[order], err[order])
        )
    G = max(1, max(len(fr[0]) for fr in frames))
    out = PersonGroups(
        labels=np.full((F, M, P), -1, np.int32),
        groups=np.full((F, G, M), -1, np.int32),
        valid=np.zeros((F, G), bool),
        points3d=np.zeros((F, G, 3), dtype),
        bpe=np.zeros((F, G), dtype),
        err_px=np.zeros((F, G), dtype),
        n_views=np.zeros((F, G), np.int32),
        num_groups=np.zeros(F, np.int32),
        group_class=np.full((F, G), -1, np.int32),
    )
    for f, (g, c, X, b, e) in enumerate(frames):
        n = len(g)
        out.groups[f, :n], out.valid[f, :n], out.group_class[f, :n] = g, True, c
        out.points3d[f, :n], out.bpe[f, :n], out.err_px[f, :n] = X, b, e
        out.n_views[f, :n] = (g >= 0).sum(axis=1)
        out.num_groups[f] = n
        k, m = np.nonzero(g >= 0)
        out.labels[f, m, g[k, m]] = k
    return out


# ------------------------------------------------------------------ people as the output


class People(NamedTuple):
    """What :func:`identify_people` returns: every frame's people as skeletons.

    Attributes:
        points: ``(F, N, C, 3)`` the 3D point (scene units) of every person's joint of every
            class, NaN where the person has no group of that class in the frame. ``N`` is the
            most people of any frame (at least 1); rows past a frame's people are NaN.
        person_id: ``(F, N)`` int32 id of every person, ``-1`` in padding rows; rows in order
            of id. Ids start at 0 in order of first appearance and are never reused; with a
            tracked result (:func:`cdog_jax.associate_sequence`, :func:`cdog_jax.track_groups`)
            a person keeps its id over frames, else ids are per frame.
        group_person: ``(F, G)`` int32 person id of every group of the result, ``-1`` where the
            group is not valid or none of its detections has a known instance.
        merged: ``(F, N)`` bool: the person holds two groups of one class (two people's joints
            in one), or took joints tracked as another person who is not seen in the frame.
        split: ``(F, N)`` bool: joints tracked as one person went to this person and to another
            person of the frame.
        mixed: ``(F, G)`` bool: the group holds detections of two people seen in one view.
        num_people: the number of ids given.
        class_names: the joint names by class id, or ``None``.
    """

    points: np.ndarray
    person_id: np.ndarray
    group_person: np.ndarray
    merged: np.ndarray
    split: np.ndarray
    mixed: np.ndarray
    num_people: int
    class_names: tuple[str, ...] | None


class PersonLinker:
    """People linked over frames through the track ids of their joints, one frame at a time
    (state: the person that owns every track id seen so far). Used offline by
    :func:`identify_people` and live by :class:`cdog_jax.LiveAssociator`."""

    def __init__(self, min_votes: int | float = 2.0):
        self.min_votes = min_votes
        self.owner: dict[int, int] = {}  # track id -> person id
        self.next_id = 0

    def step(
        self, local: np.ndarray, track_id: np.ndarray | None
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``local (G,)`` person of every group in ``0..K-1`` (-1 none), ``track_id (G,)``
        (-1 none; ``None``: ids per frame). Returns ``ids (K,)``, ``merged (K,)`` (took
        ``min_votes`` or more tracks of a known person not seen in this frame) and ``split
        (K,)`` (holds ``min_votes`` or more tracks of a person another one of the frame took).
        Each person takes the id of the known person that owns most of its groups' tracks,
        greedily, most votes first (ties: the smaller id), one to one; the others get new ids."""
        K = int(local.max()) + 1 if local.size else 0
        ids = np.full(K, -1, np.int64)
        merged, split = np.zeros(K, bool), np.zeros(K, bool)
        votes: dict[tuple[int, int], int] = {}
        if track_id is not None:
            for p, t in zip(local.tolist(), np.asarray(track_id).tolist()):
                if p >= 0 and t >= 0 and t in self.owner:
                    votes[p, self.owner[t]] = votes.get((p, self.owner[t]), 0) + 1
        taken: dict[int, int] = {}  # known person -> local person
        for (p, q), _ in sorted(votes.items(), key=lambda kv: (-kv[1], kv[0][1], kv[0][0])):
            if ids[p] < 0 and q not in taken:
                ids[p], taken[q] = q, p
        for p in range(K):
            if ids[p] < 0:
                ids[p] = self.next_id
                self.next_id += 1
        for (p, q), n in votes.items():
            if n >= self.min_votes and q != ids[p]:
                if q in taken:
                    split[p] = split[taken[q]] = True
                else:
                    merged[p] = True
        if track_id is not None:
            for p, t in zip(local.tolist(), np.asarray(track_id).tolist()):
                if p >= 0 and t >= 0:
                    self.owner[t] = int(ids[p])
        return ids, merged, split


class FramePersons(NamedTuple):
    """One frame's people (:func:`people_of_frame`): ``ids (K,)``, ``skeletons (K, C, 3)``
    (NaN: not seen), ``merged``, ``split (K,)``, and per group ``group_person (G,)`` (id, -1)
    and ``mixed (G,)``."""

    ids: np.ndarray
    skeletons: np.ndarray
    merged: np.ndarray
    split: np.ndarray
    group_person: np.ndarray
    mixed: np.ndarray


def people_of_frame(
    groups,
    valid,
    group_class,
    instances,
    points3d,
    n_views,
    err_px,
    num_classes: int,
    linker: PersonLinker,
    track_id,
    min_votes: int | float,
) -> FramePersons:
    """One frame of :func:`identify_people`: ``groups (G, M)``, ``valid``, ``group_class``,
    ``points3d (G, 3)``, ``n_views``, ``err_px (G,)`` of the result, ``instances (M, P)``;
    ``linker`` carries the ids over frames (``track_id (G,)``, or ``None``)."""
    G, C = len(valid), num_classes
    fp = frame_people(np.where(valid[:, None], groups, -1), valid, instances, min_votes)
    if fp is None:
        if track_id is not None:
            linker.step(np.full(G, -1), track_id)
        empty = np.zeros(0, bool)
        return FramePersons(
            np.zeros(0, np.int64),
            np.zeros((0, C, 3)),
            empty,
            empty,
            np.full(G, -1, np.int32),
            np.zeros(G, bool),
        )
    gp = np.where(valid, fp.group_person, -1)
    people, local = np.unique(gp[gp >= 0], return_inverse=True)
    local_of = np.full(G, -1, np.int64)
    local_of[gp >= 0] = local
    ids, temporal_merge, split = linker.step(local_of, track_id)
    K = len(people)
    skeleton = np.full((K, C, 3), np.nan)
    # Each person's joint of a class: its group of the most views, then of the smallest
    # error, then the first; a person with two groups of one class is flagged.
    g = np.flatnonzero(local_of >= 0)
    k, c = local_of[g], np.asarray(group_class)[g].astype(np.int64)
    order = np.lexsort((g, np.asarray(err_px)[g], -np.asarray(n_views)[g], c, k))
    cell = (k * C + c)[order]
    first = np.r_[True, cell[1:] != cell[:-1]] if len(cell) else np.zeros(0, bool)
    best = g[order][first]
    skeleton[local_of[best], np.asarray(group_class)[best]] = points3d[best]
    twice = np.zeros(K, bool)
    twice[k[order][~first]] = True
    group_person = np.full(G, -1, np.int32)  # (no person: ids is empty)
    group_person[local_of >= 0] = ids[local_of[local_of >= 0]]
    return FramePersons(
        ids, skeleton, twice | temporal_merge, split, group_person, fp.foreign.any(axis=1) & valid
    )


def identify_people(result, instances, *, min_votes: int | float = 2.0) -> People:
    """Who is who: the people of every frame of a classed result, as skeletons with ids.

    Args:
        result: a :class:`cdog_jax.TrackedAssociation` with classes (ids kept over frames) or
            a :class:`cdog_jax.ClassAssociation` (ids per frame), e.g. keypoints of an
            OpenPose folder through :func:`cdog_jax.associate_sequence`.
        instances: ``(F, M, P)`` int per-view instance of every detection (the 2D skeleton it
            belongs to in its view, as the detector numbered them; -1: unknown), in the
            result's slots (``load_openpose(...).instances``).
        min_votes: groups that must link two (view, instance) nodes, on average over their
            node pairs, to make them one person (as :class:`cdog_jax.PersonVote`); also the
            tracks that flag a merge or a split.

    Each frame's (view, instance) nodes are clustered into people by the groups that join
    them, under view uniqueness; a group belongs to the most frequent person of its members
    (``mixed`` when members of a person seen in one of the same views disagree). A person's
    joint of a class is its group of that class with the most views (then the smallest
    ``err_px``); two such groups flag the person ``merged``. With track ids, a person keeps
    the id of the person that owned most of its joints' tracks (:class:`PersonLinker`).
    Plain NumPy on the host (a frame holds a few dozen nodes).
    """
    return people_part(result, instances, PersonLinker(min_votes), min_votes)


def people_part(result, instances, linker: PersonLinker, min_votes: int | float = 2.0) -> People:
    """:func:`identify_people` of one part of a recording, ids continued by ``linker`` (the
    :class:`PersonLinker` of the parts before it: parts identified one after the other give
    the whole's ids); ``num_people`` counts the ids given so far."""
    assoc = result.association
    group_class = getattr(result, "group_class", None)
    if group_class is None or getattr(result, "num_classes", None) is None:
        raise ValueError(
            "identify_people needs a classed result (associate_classes, or associate_sequence with classes=)"
        )
    labels = np.asarray(assoc.labels)
    if labels.ndim != 3:
        raise ValueError(
            f"identify_people needs a result with a frame axis (labels (F, M, P)); got labels {labels.shape}"
        )
    instances = check_instances(instances, np.ones(labels.shape, bool))
    groups, valid = np.asarray(assoc.groups), np.asarray(assoc.valid)
    points3d, n_views, err = (
        np.asarray(assoc.points3d),
        np.asarray(assoc.n_views),
        np.asarray(assoc.err_px),
    )
    group_class = np.asarray(group_class)
    track = getattr(result, "track_id", None)
    track = None if track is None else np.asarray(track)
    F, G, _ = groups.shape
    C = int(result.num_classes)
    group_person = np.full((F, G), -1, np.int32)
    mixed = np.zeros((F, G), bool)
    frames = []
    for f in range(F):
        one = people_of_frame(
            groups[f],
            valid[f],
            group_class[f],
            instances[f],
            points3d[f],
            n_views[f],
            err[f],
            C,
            linker,
            None if track is None else track[f],
            min_votes,
        )
        group_person[f], mixed[f] = one.group_person, one.mixed
        frames.append((one.ids, one.skeletons, one.merged, one.split))
    N = max(1, max(len(ids) for ids, *_ in frames))
    out = People(
        points=np.full((F, N, C, 3), np.nan, points3d.dtype),
        person_id=np.full((F, N), -1, np.int32),
        group_person=group_person,
        merged=np.zeros((F, N), bool),
        split=np.zeros((F, N), bool),
        mixed=mixed,
        num_people=linker.next_id,
        class_names=result.class_names,
    )
    for f, (ids, skeleton, merged, split) in enumerate(frames):
        order = np.argsort(ids, kind="stable")
        n = len(ids)
        out.points[f, :n], out.person_id[f, :n] = skeleton[order], ids[order]
        out.merged[f, :n], out.split[f, :n] = merged[order], split[order]
    return out
