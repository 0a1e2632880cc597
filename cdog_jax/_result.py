"""The association result pytree (docs/ALGORITHM.md §11)."""

import dataclasses

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from ._runtime.stored_programs import dataclass_tree
from ._types import Array, Bool, Float, Int
from .graph._groups import compact_groups, labels_from_groups


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


def association_from_groups(
    groups: Int[Array, "G M"],
    valid: Bool[Array, " G"],
    member: Bool[Array, "G M"],
    points3d: Float[Array, "G 3"],
    bpe: Float[Array, " G"],
    err_px: Float[Array, " G"],
    num_slots: int,
    sigma_px: Float[Array, ""],
    tau_px: Float[Array, ""],
    status: Int[Array, ""],
) -> Association:
    """The one place an :class:`Association` is built: the group table ``(G, M)`` restricted
    to ``member (G, M)``, valid groups moved to the front (order kept), their points
    ``(G, 3)``, BPE (px²) and mean error (px) permuted alike and zeroed where invalid, and
    the labels ``(M, num_slots)`` rebuilt."""
    groups = jnp.where(member, groups, -1)
    groups, valid, order = compact_groups(groups, valid)
    return Association(
        labels=labels_from_groups(groups, valid, num_slots),
        groups=groups,
        valid=valid,
        points3d=jnp.where(valid[:, None], points3d[order], 0.0),
        bpe=jnp.where(valid, bpe[order], 0.0),
        err_px=jnp.where(valid, err_px[order], 0.0),
        n_views=jnp.sum(groups >= 0, dtype=jnp.int32, axis=1),
        num_groups=jnp.sum(valid, dtype=jnp.int32),
        sigma_px=sigma_px,
        tau_px=tau_px,
        status=status,
    )


def batched_association(*, on_host: bool = False, **fields) -> Association:
    """An :class:`Association` with a leading axis (frames or scenes) from its fields (host
    or device arrays), on the device in one transfer, or as NumPy arrays with ``on_host`` (a
    caller that reads them on the host: no transfer there and back). Built from the pytree's
    leaves, so that nothing runs eagerly: a ``vmap`` of the constructor traced new operations
    for every new group count."""
    names = tuple(
        field.name for field in dataclasses.fields(Association)
    )  # the pytree's leaf order
    leaves = [np.asarray(fields[name]) for name in names]
    return jax.tree.unflatten(
        dataclass_tree(Association, names), leaves if on_host else jax.device_put(leaves)
    )
