"""The exact reference on small scenes: cliques of the gated epipolar graph, chosen by an
integer program.

After the multi-view matching formulations that enumerate candidate cliques of a
pairwise-gated graph and select disjoint ones by integer linear programming (e.g. the
clique/set-packing programs of cvlab-epfl's multiview matching, and correlation clustering:
Bansal, Blum & Chawla, 2004, "Correlation clustering", Machine Learning 56). A host method:
NumPy and ``scipy.optimize.milp`` on the CPU, never jitted (``pip install "cdog-jax[exact]"``).
"""

from __future__ import annotations

import dataclasses
from typing import ClassVar

import numpy as np

from .._method import HostGroupTableMethod, register_method

MAX_POINTS = 15
"""The largest scene (detections in any one view) the exact method accepts."""

MAX_CLIQUES = 200_000
"""The most cliques the integer program is built over (a clear error beyond)."""


def gated_cost(d: np.ndarray, mask: np.ndarray) -> np.ndarray:
    """``(N, N)`` float64 symmetric epipolar cost ``½ (d[m, i, n, j] + d[n, j, m, i])`` (px)
    between nodes ``m · P + i``; ``+inf`` within a view, for padding and for non-numbers."""
    M, P = mask.shape
    d = np.asarray(d, np.float64)
    ok = mask[:, :, None, None] & mask[None, None] & ~np.isnan(d)
    d = np.where(ok, d, np.inf)
    c = 0.5 * (d + d.transpose(2, 3, 0, 1))
    same_view = np.arange(M)[:, None, None, None] == np.arange(M)[None, None, :, None]
    return np.where(same_view, np.inf, c).reshape(M * P, M * P)


def enumerate_cliques(
    cost: np.ndarray, tau: float, max_cliques: int = MAX_CLIQUES
) -> list[tuple[int, ...]]:
    """Every clique of ≥ 2 nodes of the graph whose edges are ``cost < tau`` (px), as sorted
    node tuples. Within-view pairs cost ``+inf``, so a clique has at most one node per view."""
    adjacent = cost < tau
    cliques: list[tuple[int, ...]] = []

    def extend(clique: tuple[int, ...], candidates: np.ndarray) -> None:
        for k, v in enumerate(candidates):
            grown = clique + (int(v),)
            cliques.append(grown)
            if len(cliques) > max_cliques:
                raise ValueError(
                    f"exact: more than {max_cliques} cliques in the gated graph; the scene is too dense for the exact method"
                )
            rest = candidates[k + 1 :]
            extend(grown, rest[adjacent[v, rest]])

    for u in range(cost.shape[0]):
        later = np.flatnonzero(adjacent[u])
        extend((u,), later[later > u])
    return cliques


def clique_cost(cost: np.ndarray, clique, tau: float) -> float:
    """The cost of one group (nodes ``clique``): ``Σ_{a<b} (cost[a, b] − τ)`` over its pairs
    (px). Negative for a clique of the gated graph, and more negative the larger it is: a
    detection joins a group whenever its summed cost to the members is below τ per member."""
    nodes = np.asarray(sorted(clique))
    a, b = np.triu_indices(nodes.size, 1)
    return float(np.sum(cost[nodes[a], nodes[b]] - tau))


def exact_groups(
    d: np.ndarray, mask: np.ndarray, tau: float
) -> tuple[np.ndarray, np.ndarray, float]:
    """The disjoint cliques of least total :func:`clique_cost` (each detection in at most
    one), by integer programming. ``d (M, P, M, P)`` epipolar distances (px), ``mask (M, P)``,
    ``tau`` the gate (px). Returns ``groups (G, M)`` int32 (slot per view or -1, ``G = M·P // 2``,
    valid groups first, ordered by their smallest node ``m · P + i``), ``valid (G,)`` and the
    optimal cost (px)."""
    try:
        # scipy loads with this method alone (scipy ships with jax)
        from scipy.optimize import Bounds, LinearConstraint, milp
        from scipy.sparse import csr_array
    except ImportError as error:  # pragma: no cover - scipy ships with jax
        raise ImportError('the exact method needs scipy: pip install "cdog-jax[exact]"') from error
    mask = np.asarray(mask, bool)
    M, P = mask.shape
    G = max(M * P // 2, 1)
    cost = gated_cost(d, mask)
    cliques = enumerate_cliques(cost, float(tau))
    groups = np.full((G, M), -1, np.int32)
    valid = np.zeros((G,), bool)
    if not cliques:
        return groups, valid, 0.0
    weights = np.asarray([clique_cost(cost, c, float(tau)) for c in cliques])
    rows = np.concatenate([np.asarray(c) for c in cliques])
    cols = np.repeat(np.arange(len(cliques)), [len(c) for c in cliques])
    packing = csr_array((np.ones(rows.size), (rows, cols)), shape=(M * P, len(cliques)))
    solution = milp(
        weights,
        constraints=LinearConstraint(packing, -np.inf, 1.0),
        integrality=np.ones(len(cliques)),
        bounds=Bounds(0.0, 1.0),
    )
    if solution.x is None:  # pragma: no cover - x = 0 is always feasible
        raise RuntimeError(f"exact: the integer program failed: {solution.message}")
    chosen = sorted((cliques[k] for k in np.flatnonzero(solution.x > 0.5)), key=min)
    for g, clique in enumerate(chosen):
        for node in clique:
            groups[g, node // P] = node % P
        valid[g] = True
    return groups, valid, float(np.sum(weights[solution.x > 0.5]))


@dataclasses.dataclass(frozen=True)
class Exact(HostGroupTableMethod):
    """The exact reference (``"exact"``): the disjoint cliques of the gated epipolar graph of
    least total cost, by integer programming (:func:`exact_groups`).

    Edges join detections of different views whose symmetric epipolar cost is below the
    shared σ-matched gate ``τ = max(2·√2·σ, 1 px)``; a clique (at most one detection per
    view) costs ``Σ_{pairs} (c − τ)`` (:func:`clique_cost`); the integer program picks
    disjoint cliques of least total cost. Then the shared DLT point and validity gate of
    every group-table method. A host method (``jittable = False``): NumPy and
    ``scipy.optimize.milp`` per scene, for scenes of at most :data:`MAX_POINTS` detections
    per view. Its optimum shows how far each method's groups are from the best of that cost.
    """

    HOST_NAME: ClassVar[str] = "exact"
    HOST_TOOLS: ClassVar[str] = "NumPy, scipy.optimize.milp"

    def check_scene(self, mask, where: str) -> None:
        counts = np.sum(np.asarray(mask, bool), axis=-1)
        if counts.max(initial=0) > MAX_POINTS:
            view = int(np.argmax(counts))
            raise ValueError(
                f"{where}: the exact method handles scenes of at most {MAX_POINTS} points "
                f"(detections per view); view {view} has {int(counts[view])}"
            )

    def host_groups(self, rig, xy, mask, d, tau, thresholds):
        groups, valid, _ = exact_groups(d, mask, tau)
        return groups, valid


register_method("exact", Exact)
