"""The association result pytree (docs/ALGORITHM.md §11)."""

import equinox as eqx

from ._types import Array, Bool, Float, Int


class Association(eqx.Module):
    """What :func:`cdog_jax.associate` returns for one scene (a batch adds a leading ``B``).

    Valid groups come first: ``groups[:num_groups]`` are the groups, in a deterministic
    order (by their smallest node index ``m * P + i`` after the graph stages).

    Attributes:
        labels: ``(M, P)`` int32 group id of every detection, ``-1`` if unassigned or padding.
        groups: ``(G, M)`` int32 slot index of the group's detection in each view, or ``-1``.
        valid: ``(G,)`` bool, the group exists (``G = M * P // 2`` is a static capacity).
        points3d: ``(G, 3)`` multi-view DLT (or refined) 3D point, scene units; 0 if invalid.
        bpe: ``(G,)`` back-projection error ``mean_m ‖π_m(X) − x_m‖²`` over members (px²).
        err_px: ``(G,)`` mean reprojection distance over members (px).
        n_views: ``(G,)`` int32 number of member views.
        num_groups: ``()`` int32 count of valid groups.
        sigma_px: ``()`` the noise level used (given, or estimated when ``sigma="auto"``:
            1 px when the estimate falls back, see ``status``).
        tau_px: ``()`` the epipolar gate used.
        status: ``()`` int32 bit flags of :class:`cdog_jax.Status` (0: nothing to report;
            e.g. a loop that stopped at its bound, or σ estimated by its fallback).
    """

    labels: Int[Array, "M P"]
    groups: Int[Array, "G M"]
    valid: Bool[Array, " G"]
    points3d: Float[Array, "G 3"]
    bpe: Float[Array, " G"]
    err_px: Float[Array, " G"]
    n_views: Int[Array, " G"]
    num_groups: Int[Array, ""]
    sigma_px: Float[Array, ""]
    tau_px: Float[Array, ""]
    status: Int[Array, ""]
