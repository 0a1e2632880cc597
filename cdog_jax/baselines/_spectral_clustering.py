"""Spectral clustering of the epipolar affinity graph.

Source: A. Y. Ng, M. I. Jordan and Y. Weiss (2001), "On spectral clustering: analysis and
an algorithm" (NeurIPS), with the number of clusters from the eigengap (U. von Luxburg
(2007), "A tutorial on spectral clustering", §8.3), applied to the graph whose nodes are
detections and whose edges are gated epipolar affinities.

As implemented here:

1. ``W`` is the epipolar affinity of ``_epipolar_affinity`` (a Gaussian of the symmetric
   epipolar distance inside the σ-matched gate ``τ``, scale ``affinity_width·τ``; no
   self-loops). Detections with no edge (degree 0) and padding are left out: they end
   unassigned.
2. The normalised affinity ``D^{-1/2} W D^{-1/2}`` (the normalised Laplacian is ``I`` minus it)
   is diagonalised with ``jnp.linalg.eigh`` (static ``N × N``). With eigenvalues
   ``e_1 ≥ e_2 ≥ …``, the number of clusters is ``k = argmax (e_i − e_{i+1})`` over
   ``k_min ≤ i ≤ max_clusters`` (first of equal gaps): each connected component contributes
   an eigenvalue exactly 1, so in a scene whose gated graph has one component per point
   the largest gap follows the last 1. ``k_min`` is the largest number of connected
   detections in one view, as no view-unique partition has fewer clusters: without it, at
   σ = 3 px on 10 views × 50 points the gated graph is nearly one component, the largest
   gap came after the first few eigenvalues and pair recall fell to 0.007.
   ``max_clusters`` is static (default ``N // 2``, the most groups of ≥ 2 nodes).
3. The rows of the top-``k`` eigenvectors (later columns masked to 0), normalised to unit
   length, are clustered by k-means: deterministic farthest-point initialisation (the first
   centre is the node of largest degree, ties to the smallest index; each next one the node
   farthest from its nearest centre) and a fixed number of Lloyd iterations
   (``kmeans_iterations``, static; the count is part of the method, so the status is 0).
4. View-uniqueness: in each cluster, of several members in one view only the one with the
   largest total affinity to the cluster's other members is kept (ties: smallest slot);
   the others are unassigned. Clusters left with ≥ 2 detections are the groups.
"""

import dataclasses
from typing import ClassVar

import jax
import jax.numpy as jnp

from .._method import GroupTableMethod, register_method
from .._types import Array, Bool, Float, Int
from ..geometry._camera import Rig
from ..graph._groups import groups_from_labels
from ._epipolar_affinity import epipolar_affinity


@dataclasses.dataclass(frozen=True)
class SpectralClusteringOptions:
    """Parameters of spectral clustering (Ng, Jordan & Weiss 2001; eigengap as in von
    Luxburg 2007).

    Attributes:
        max_clusters: static bound on ``k`` (default ``None``: ``N // 2``).
        kmeans_iterations: static number of Lloyd iterations.
        affinity_width: affinity scale as a fraction of the gate ``τ`` (traced).
    """

    max_clusters: int | None = None
    kmeans_iterations: int = 20
    affinity_width: float = 1.0
    THRESHOLDS: ClassVar[tuple[str, ...]] = ("affinity_width",)

    def __post_init__(self):
        if self.max_clusters is not None and (
            not isinstance(self.max_clusters, int) or self.max_clusters < 1
        ):
            raise ValueError(
                f"SpectralClusteringOptions.max_clusters must be None or an int >= 1; got {self.max_clusters!r}"
            )
        if not isinstance(self.kmeans_iterations, int) or self.kmeans_iterations < 0:
            raise ValueError(
                f"SpectralClusteringOptions.kmeans_iterations must be an int >= 0; got {self.kmeans_iterations!r}"
            )


def _farthest_point_centres(points, active, degree, k, num_centres):
    """``(K,)`` node indices of ``k`` (traced, ``≤ K``) farthest-point centres; unused ones 0."""
    N = points.shape[0]
    node = jnp.arange(N, dtype=jnp.int32)

    def first_best(key, ok):
        key = jnp.where(ok, key, -jnp.inf)
        return jnp.min(jnp.where(ok & (key == jnp.max(key)), node, N)).astype(jnp.int32)

    first = first_best(degree, active)
    nearest = jnp.sum((points - points[first][None, :]) ** 2, axis=1)

    def body(c, carry):
        centres, nearest = carry
        nxt = first_best(nearest, active)
        use = c < k
        centres = centres.at[c].set(jnp.where(use, nxt, 0))
        dist = jnp.sum((points - points[nxt][None, :]) ** 2, axis=1)
        return centres, jnp.where(use, jnp.minimum(nearest, dist), nearest)

    centres = jnp.zeros((num_centres,), jnp.int32).at[0].set(first)
    centres, _ = jax.lax.fori_loop(1, num_centres, body, (centres, nearest))
    return centres


def _kmeans(points, active, centres, k, iterations):
    """Cluster index ``(N,)`` of every node after ``iterations`` Lloyd steps from ``centres
    (K, D)`` (only the first ``k`` are used)."""
    K = centres.shape[0]
    used = jnp.arange(K, dtype=jnp.int32) < k

    def assign(centres):
        dist = jnp.sum((points[:, None, :] - centres[None, :, :]) ** 2, axis=-1)  # (N, K)
        return jnp.argmin(jnp.where(used[None, :], dist, jnp.inf), axis=1).astype(jnp.int32)

    def body(_, centres):
        member = (assign(centres)[:, None] == jnp.arange(K, dtype=jnp.int32)[None, :]) & active[
            :, None
        ]
        count = jnp.sum(member, axis=0).astype(points.dtype)  # (K,)
        total = jnp.einsum("nk,nd->kd", member.astype(points.dtype), points)
        # An empty cluster keeps its centre.
        return jnp.where((count > 0)[:, None], total / jnp.maximum(count, 1.0)[:, None], centres)

    return assign(jax.lax.fori_loop(0, iterations, body, centres))


def spectral_clustering_groups(
    rig: Rig,
    xy: Float[Array, "M P 2"],
    mask: Bool[Array, "M P"],
    d: Float[Array, "M P M P"],
    tau: Float[Array, ""],
    sigma: Float[Array, ""],
    thresholds: dict[str, Float[Array, ""]],
    options: SpectralClusteringOptions,
) -> tuple[Int[Array, "G M"], Bool[Array, " G"], Int[Array, ""]]:
    """Spectral-clustering groups of one scene (module docstring): ``groups (G, M)`` (slot
    or -1), ``valid (G,)`` with ``G = M·P // 2``, and status 0."""
    M, P = mask.shape
    N = M * P
    dtype = d.dtype
    width = jnp.asarray(thresholds["affinity_width"], dtype)
    W = epipolar_affinity(d, mask, jnp.asarray(tau, dtype), width)
    degree = jnp.sum(W, axis=1)
    active = mask.reshape(N) & (degree > 0)
    inv_sqrt = jnp.where(active, 1.0 / jnp.sqrt(jnp.where(active, degree, 1.0)), 0.0)
    eigenvalues, vectors = jnp.linalg.eigh(inv_sqrt[:, None] * W * inv_sqrt[None, :])
    eigenvalues, vectors = eigenvalues[::-1], vectors[:, ::-1]

    K = max(N // 2 if options.max_clusters is None else min(options.max_clusters, N - 1), 1)
    gaps = eigenvalues[:K] - eigenvalues[1 : K + 1]  # gaps[i]: after the (i + 1)-th eigenvalue
    # No view-unique partition has fewer clusters than the fullest view has detections.
    fewest = jnp.clip(jnp.max(jnp.sum(active.reshape(M, P), axis=1, dtype=jnp.int32)), 1, K)
    rank = jnp.arange(1, K + 1, dtype=jnp.int32)
    k = (jnp.argmax(jnp.where(rank >= fewest, gaps, -jnp.inf)) + 1).astype(
        jnp.int32
    )  # first largest gap
    embedding = jnp.where(jnp.arange(K, dtype=jnp.int32)[None, :] < k, vectors[:, :K], 0.0)
    norm = jnp.sqrt(jnp.sum(embedding * embedding, axis=1))
    ok = active & (norm > 0)
    points = jnp.where(ok[:, None], embedding / jnp.where(ok, norm, 1.0)[:, None], 0.0)

    centres = _farthest_point_centres(points, ok, degree, k, K)
    cluster = _kmeans(points, ok, points[centres], k, options.kmeans_iterations)
    labels, keep = _view_unique(cluster, ok, W, M, P)
    groups, group_valid = groups_from_labels(labels, keep, M, P)
    return groups, group_valid, jnp.int32(0)


def _view_unique(cluster, ok, W, num_views, num_slots):
    """Per cluster and view, keep the member of largest affinity to the cluster's others.

    Returns node labels (the smallest kept node of each cluster, as ``groups_from_labels``
    expects; a dropped node labels itself) and the kept nodes ``(N,)``."""
    N = cluster.shape[0]
    node = jnp.arange(N, dtype=jnp.int32)
    view = node // num_slots
    same = ok[:, None] & ok[None, :] & (cluster[:, None] == cluster[None, :])
    support = jnp.sum(jnp.where(same, W, 0.0), axis=1)
    key = jnp.where(ok, support, -jnp.inf)
    best = jnp.full((N, num_views), -jnp.inf, key.dtype).at[cluster, view].max(key)
    tied = ok & (key == best[cluster, view])
    first = jnp.full((N, num_views), N, jnp.int32).at[cluster, view].min(jnp.where(tied, node, N))
    keep = ok & (first[cluster, view] == node)
    smallest = jnp.full((N,), N, jnp.int32).at[jnp.where(keep, cluster, N)].min(node, mode="drop")
    labels = jnp.where(keep, smallest[cluster], node)
    return labels, keep


@dataclasses.dataclass(frozen=True)
class SpectralClustering(GroupTableMethod, SpectralClusteringOptions):
    """Spectral clustering of the epipolar affinity graph as a registered method (``"spectral_clustering"``): the options and algorithm of
    :class:`SpectralClusteringOptions`, with the σ, gate, triangulation and validity gate every group-table
    method shares (:class:`cdog_jax.GroupTableMethod`).
    """

    GROUPS = staticmethod(spectral_clustering_groups)


register_method("spectral_clustering", SpectralClustering)
