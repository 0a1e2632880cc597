"""ST-cut with 3D back-projection: the gated epipolar graph, weighted by how well each
pair's two-view point back-projects into the other views, split by s-t minimum cuts until
every group holds at most one detection per view.

After Vogiatzis, Torr & Cipolla (2005), "Multi-view stereo via volumetric graph-cuts"
(CVPR), who label a graph by its s-t minimum cut with capacities from multi-view
photo-consistency of 3D locations; here the 3D locations are the two-view points of the
candidate matches, photo-consistency becomes back-projection support (a detection near the
point's projection in another view), and repeated s-t cuts separate two detections of one
view (max-flow / min-cut: Ford & Fulkerson 1956; Dinic's algorithm). The published
association baseline gives no exact formulation; this one is our design from those sources.
A host method: NumPy and ``scipy.sparse.csgraph.maximum_flow`` on the CPU, never jitted
(scipy: ``pip install "cdog-jax[exact]"``).
"""

from __future__ import annotations

import dataclasses
import math
from typing import ClassVar

import numpy as np

from .._method import HostGroupTableMethod, register_method
from ..geometry._camera import Rig
from ._exact import gated_cost

CAPACITY_SCALE = 1000
"""Integer capacities: ``1 + round(CAPACITY_SCALE · weight)`` (max-flow needs integers;
a smaller scale when the capacities would sum beyond 2²⁹)."""


def _scipy():
    try:
        # scipy loads with this method alone (scipy ships with jax)
        from scipy.sparse import csr_array
        from scipy.sparse.csgraph import breadth_first_order, connected_components, maximum_flow
        from scipy.spatial import cKDTree
    except ImportError as error:  # pragma: no cover - scipy ships with jax
        raise ImportError('the st_cut method needs scipy: pip install "cdog-jax[exact]"') from error
    return csr_array, breadth_first_order, connected_components, maximum_flow, cKDTree


def candidate_edges(cost: np.ndarray, tau: float, M: int, P: int, per_view: int) -> np.ndarray:
    """``(E, 2)`` int undirected edges ``u < v`` (nodes ``m · P + i``): each detection's
    ``per_view`` cheapest partners with ``cost < tau`` (px) in every other view, both ends
    pooled (an edge is kept when either end keeps it)."""
    by_view = cost.reshape(M * P, M, P)
    order = np.argsort(by_view, axis=2, kind="stable")[:, :, :per_view]  # (N, M, K)
    kept = np.take_along_axis(by_view, order, axis=2) < tau
    u = np.broadcast_to(np.arange(M * P)[:, None, None], order.shape)[kept]
    v = (np.arange(M)[None, :, None] * P + order)[kept]
    pairs = np.unique(np.stack([np.minimum(u, v), np.maximum(u, v)], axis=1), axis=0)
    return pairs.reshape(-1, 2).astype(np.int64)


def _two_view_points(
    proj: np.ndarray, xy: np.ndarray, a: np.ndarray, b: np.ndarray, P: int
) -> np.ndarray:
    """``(E, 3)`` DLT points of the node pairs ``(a, b)``; ``proj (M, 3, 4)``, ``xy (M, P, 2)`` px."""
    rows = []
    for node in (a, b):
        Pm, x = proj[node // P], xy[node // P, node % P]
        rows += [x[:, 0, None] * Pm[:, 2] - Pm[:, 0], x[:, 1, None] * Pm[:, 2] - Pm[:, 1]]
    A = np.stack(rows, axis=1)
    A = A / np.maximum(np.linalg.norm(A, axis=2, keepdims=True), 1e-300)
    h = np.linalg.svd(A)[2][:, -1]
    with np.errstate(divide="ignore", invalid="ignore"):
        return h[:, :3] / h[:, 3:]


def projection_matrices(rig: Rig) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """``K, R, t`` of ``rig`` as float64 arrays and the projections ``K [R | t]`` ``(M, 3, 4)``."""
    K, R, t = (np.asarray(a, np.float64) for a in (rig.K, rig.R, rig.t))
    return K, R, t, rig.host_proj()


def edge_points(
    rig: Rig, xy: np.ndarray, edges: np.ndarray, P: int
) -> tuple[np.ndarray, np.ndarray]:
    """``(E, 3)`` two-view DLT points of the edges and ``(E,)`` whether each is usable
    (finite and in front of both of its own cameras)."""
    _, R, t, proj = projection_matrices(rig)
    a, b = edges[:, 0], edges[:, 1]
    X = _two_view_points(proj, xy, a, b, P)
    finite = np.all(np.isfinite(X), axis=1)
    X = np.where(finite[:, None], X, 0.0)
    depth = (
        np.einsum("ej,ej->e", R[a // P, 2], X) + t[a // P, 2],
        np.einsum("ej,ej->e", R[b // P, 2], X) + t[b // P, 2],
    )
    return X, finite & (depth[0] > 0) & (depth[1] > 0)


def _project(rig: Rig, X: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(E, M, 2)`` pixels of the points ``X (E, 3)`` in every view and ``(E, M)`` in front."""
    K, R, t, _ = projection_matrices(rig)
    cam = np.einsum("mij,ej->emi", R, X) + t[None]
    pix = np.einsum("mij,emj->emi", K, cam)
    with np.errstate(divide="ignore", invalid="ignore"):
        return pix[..., :2] / pix[..., 2:], cam[..., 2] > 0


def backprojection_support(
    rig: Rig,
    xy: np.ndarray,
    mask: np.ndarray,
    edges: np.ndarray,
    X: np.ndarray,
    usable: np.ndarray,
    radius: float,
) -> np.ndarray:
    """``(E,)`` the support of each edge's two-view point ``X (E, 3)``: over the other views
    where it lies in front of the camera, ``Σ max(0, 1 − e / radius)`` with ``e`` the
    distance (px) from its projection to the nearest detection there; 0 when not ``usable``."""
    *_, cKDTree = _scipy()
    M, P = mask.shape
    pix, front = _project(rig, X)
    support = np.zeros(len(edges))
    for n in range(M):
        detected = xy[n][mask[n]]
        other = usable & (edges[:, 0] // P != n) & (edges[:, 1] // P != n) & front[:, n]
        if not detected.shape[0] or not other.any():
            continue
        e, _ = cKDTree(detected).query(pix[other, n], k=1)
        support[other] += np.maximum(0.0, 1.0 - e / radius)
    return support


def back_projection_seeds(
    rig: Rig, xy: np.ndarray, nodes: np.ndarray, node: int, X: np.ndarray, P: int, radius: float
) -> np.ndarray:
    """The detections among ``nodes`` (global ids) that the 3D point ``X (3,)`` projects onto:
    ``node`` and, in every other view where ``X`` is in front, the nearest detection within
    ``radius`` px of its projection. Local indices into ``nodes``."""
    pix, front = _project(rig, X[None])
    views = nodes // P
    e = np.linalg.norm(xy[views, nodes % P] - pix[0, views], axis=1)
    e = np.where(front[0, views] & (views != node // P) & np.isfinite(e), e, np.inf)
    seeds = [int(np.flatnonzero(nodes == node)[0])]
    for n in np.unique(views[np.isfinite(e) & (e < radius)]):
        here = np.flatnonzero(views == n)
        seeds.append(int(here[np.lexsort((nodes[here], e[here]))[0]]))
    return np.asarray(seeds)


def min_cut_source_side(capacity, sources: np.ndarray, sinks: np.ndarray) -> np.ndarray:
    """``(n,)`` bool: the source side of the minimum cut of the symmetric integer
    ``capacity (n, n)`` matrix between the node sets ``sources`` and ``sinks`` (each tied
    to its terminal by an edge no cut can take; the smallest such side: the nodes the
    residual graph reaches from the source terminal)."""
    csr_array, breadth_first_order, _, maximum_flow, _ = _scipy()
    n = capacity.shape[0]
    unbreakable = int(capacity.sum()) + 1
    rows = np.concatenate([capacity.tocoo().row, np.full(sources.size, n), sinks])
    cols = np.concatenate([capacity.tocoo().col, sources, np.full(sinks.size, n + 1)])
    data = np.concatenate(
        [capacity.tocoo().data, np.full(sources.size + sinks.size, unbreakable)]
    ).astype(np.int32)
    graph = csr_array((data, (rows, cols)), shape=(n + 2, n + 2))
    flow = maximum_flow(graph, n, n + 1, method="dinic").flow
    residual = csr_array(graph - flow)
    residual.data = (residual.data > 0).astype(np.int32)
    residual.eliminate_zeros()
    side = np.zeros(n + 2, bool)
    side[breadth_first_order(residual, n, directed=True, return_predecessors=False)] = True
    return side[:n]


def _pick_terminals(nodes: np.ndarray, strength: np.ndarray, P: int) -> tuple[int, int] | None:
    """Two detections of one view in ``nodes`` to separate (global ids), or None when the
    nodes are view-unique: in the view with the most detections (ties: smaller view), the
    two of largest ``strength`` (ties: smaller node)."""
    views = nodes // P
    counts = np.bincount(views)
    if counts.max() < 2:
        return None
    crowded = np.flatnonzero(views == int(np.argmax(counts)))
    ranked = crowded[np.lexsort((nodes[crowded], -strength[crowded]))]
    return int(nodes[ranked[0]]), int(nodes[ranked[1]])


def st_cut_groups(
    rig: Rig,
    xy: np.ndarray,
    mask: np.ndarray,
    d: np.ndarray,
    tau: float,
    reprojection_gate: float,
    per_view: int,
) -> tuple[np.ndarray, np.ndarray, int]:
    """The groups of the back-projection-weighted gated graph split by s-t minimum cuts
    (:class:`StCutOptions`).

    Args:
        rig: the cameras (``M`` views); xy: ``(M, P, 2)`` pixels; mask: ``(M, P)``;
        d: ``(M, P, M, P)`` epipolar distances (px); tau: the gate (px);
        reprojection_gate: the back-projection radius in units of ``tau``;
        per_view: the cheapest partners kept per detection and other view.

    Returns:
        ``groups (G, M)`` int32 (slot per view or -1, ``G = M·P // 2``, valid groups first,
        ordered by their smallest node ``m · P + i``), ``valid (G,)`` and the number of s-t
        cuts made.
    """
    csr_array, _, connected_components, _, _ = _scipy()
    mask = np.asarray(mask, bool)
    M, P = mask.shape
    G, N = max(M * P // 2, 1), M * P
    xy = np.where(mask[..., None], np.asarray(xy, np.float64), 0.0)
    radius = reprojection_gate * float(tau)
    cost = gated_cost(d, mask)
    edges = candidate_edges(cost, float(tau), M, P, per_view)
    groups, valid = np.full((G, M), -1, np.int32), np.zeros((G,), bool)
    if not len(edges):
        return groups, valid, 0
    X, usable = edge_points(rig, xy, edges, P)
    support = backprojection_support(rig, xy, mask, edges, X, usable, radius)
    edge_cost = cost[edges[:, 0], edges[:, 1]]
    weight = (1.0 - edge_cost / float(tau)) + support
    scale = min(
        CAPACITY_SCALE, 2**29 / (2.0 * np.sum(1.0 + weight))
    )  # every sum stays within int32
    cap = 1 + np.round(scale * weight).astype(np.int64)
    ends = np.concatenate([edges, edges[:, ::-1]])
    capacity = csr_array(
        (np.concatenate([cap, cap]).astype(np.int32), (ends[:, 0], ends[:, 1])), shape=(N, N)
    )

    def point_of(node: int, nodes: np.ndarray) -> np.ndarray | None:
        mine = np.flatnonzero(
            ((edges[:, 0] == node) & np.isin(edges[:, 1], nodes))
            | ((edges[:, 1] == node) & np.isin(edges[:, 0], nodes))
        )
        mine = mine[usable[mine]]  # the point of a node: its edge of most support, then least cost
        return None if not mine.size else X[mine[np.lexsort((edge_cost[mine], -support[mine]))[0]]]

    def seeds(node: int, nodes: np.ndarray) -> np.ndarray:
        point = point_of(node, nodes)
        if point is None:
            return np.flatnonzero(nodes == node)
        return back_projection_seeds(rig, xy, nodes, node, point, P, radius)

    def pieces(nodes: np.ndarray) -> list[np.ndarray]:
        count, labels = connected_components(capacity[nodes][:, nodes], directed=False)
        return [nodes[labels == k] for k in range(count)]

    todo, done, cuts = pieces(np.unique(edges)), [], 0
    while todo:
        nodes = todo.pop()
        sub = capacity[nodes][:, nodes]
        terminals = _pick_terminals(nodes, np.asarray(sub.sum(axis=1)).ravel(), P)
        if terminals is None:
            done.append(nodes)
            continue
        source, sink = seeds(terminals[0], nodes), seeds(terminals[1], nodes)
        both = np.intersect1d(source, sink)  # claimed by both points: left to the cut
        source, sink = (
            np.setdiff1d(source, both[nodes[both] != terminals[0]]),
            np.setdiff1d(sink, both[nodes[both] != terminals[1]]),
        )
        side = min_cut_source_side(sub, source, sink)
        if (
            side[sink].any() or not side[source].all()
        ):  # pragma: no cover - max-flow / min-cut theorem
            raise RuntimeError("st_cut: a minimum cut failed to separate its terminals")
        cuts += 1
        todo += [p for part in (nodes[side], nodes[~side]) for p in pieces(part) if p.size >= 2]
    for g, nodes in enumerate(sorted(done, key=lambda n: int(n.min()))):
        groups[g, nodes // P] = nodes % P
        valid[g] = True
    return groups, valid, cuts


@dataclasses.dataclass(frozen=True)
class StCutOptions:
    """ST-cut with 3D back-projection (after Vogiatzis, Torr & Cipolla, 2005; our design).

    1. The gated graph: each detection's ``candidates_per_view`` cheapest partners in every
       other view with symmetric epipolar cost ``c = ½ (d[m, i, n, j] + d[n, j, m, i]) < τ``
       (the shared σ-matched gate ``τ = max(2·√2·σ, 1 px)``).
    2. Back-projection capacities: each edge's two-view DLT point is projected into the other
       views where it lies in front; a detection within ``r = reprojection_gate · τ`` px of
       the projection supports it by ``1 − e / r``. An edge's weight is ``(1 − c / τ)`` plus
       its summed support (0 for a point behind either of its own cameras); its capacity,
       both directions, is ``1 + round(1000 · weight)``.
    3. s-t cuts: while a connected piece holds two detections of one view, the two of
       largest weighted degree in its most crowded view are the terminals; each is tied, by
       an edge no cut can take, to the detections its 3D point (its edge of most support in
       the piece, then least cost) back-projects onto: the nearest within ``r`` in each other
       view (one claimed by both terminals is left to the cut). The minimum s-t cut
       (``scipy.sparse.csgraph.maximum_flow``, Dinic; the source side is what the residual
       graph reaches from the source) splits the piece, and the connected pieces of both
       sides go on. Each cut separates two nodes, so there are fewer
       than ``N = M·P`` cuts and the status is always 0. View-unique pieces of ≥ 2
       detections are the groups.

    Noise-free, every point seen in ≥ 2 views is grouped exactly when every pair of
    detections of different points costs at least τ (no wrong edge, no cut needed).

    Attributes:
        reprojection_gate: the back-projection radius in units of τ (``2 τ ≈ 5.7 σ``, as voting).
        candidates_per_view: static ``K ≥ 1``; partners kept per detection and other view.
    """

    reprojection_gate: float = 2.0
    candidates_per_view: int = 2

    def __post_init__(self):
        g, k = self.reprojection_gate, self.candidates_per_view
        if isinstance(g, bool) or not isinstance(g, (int, float)) or not math.isfinite(g) or g <= 0:
            raise ValueError(
                f"StCutOptions.reprojection_gate must be a finite number > 0; got {g!r}"
            )
        if not isinstance(k, int) or isinstance(k, bool) or k < 1:
            raise ValueError(f"StCutOptions.candidates_per_view must be an int >= 1; got {k!r}")


@dataclasses.dataclass(frozen=True)
class StCut(HostGroupTableMethod, StCutOptions):
    """ST-cut with 3D back-projection (``"st_cut"``): the groups of :class:`StCutOptions`
    (:func:`st_cut_groups`), then the shared DLT point and validity gate of every
    group-table method. A host method (``jittable = False``): NumPy and
    ``scipy.sparse.csgraph.maximum_flow`` per scene on the CPU (``pip install "cdog-jax[exact]"``).
    """

    HOST_NAME: ClassVar[str] = "st_cut"
    HOST_TOOLS: ClassVar[str] = "NumPy, scipy max-flow"

    def host_groups(self, rig, xy, mask, d, tau, thresholds):
        groups, valid, _ = st_cut_groups(
            rig, xy, mask, d, tau, float(thresholds.reprojection_gate), self.candidates_per_view
        )
        return groups, valid


register_method("st_cut", StCut)
