"""Rigs compared up to the gauge a refinement cannot fix: a similarity alignment of one rig
onto another (Umeyama on the camera centres) and the per-view errors after it."""

from __future__ import annotations

import functools
from typing import NamedTuple

import jax
import jax.numpy as jnp

from .._expect import expect_args
from .._types import Array, Float
from ..geometry._camera import Rig
from ..geometry._parameters import so3_log


class RigErrors(NamedTuple):
    """Per-view errors of a rig against a reference (:func:`rig_errors`).

    Attributes:
        rotation_deg: ``(M,)`` angle of ``R_est R_refᵀ`` (degrees).
        center: ``(M,)`` camera centre distance (scene units of the reference).
        focal_rel: ``(M,)`` relative focal error, the larger of ``fx`` and ``fy``.
        principal_px: ``(M,)`` principal point distance (pixels).
    """

    rotation_deg: Float[Array, " M"]
    center: Float[Array, " M"]
    focal_rel: Float[Array, " M"]
    principal_px: Float[Array, " M"]


def _similarity(src: Float[Array, "M 3"], dst: Float[Array, "M 3"]):
    """Umeyama: ``(s, Q, c)`` minimising ``Σ ‖dst − (s Q src + c)‖²`` (rotation ``Q``)."""
    mu_s, mu_d = jnp.mean(src, axis=0), jnp.mean(dst, axis=0)
    a, b = src - mu_s[None], dst - mu_d[None]
    U, D, Vt = jnp.linalg.svd(jnp.einsum("mi,mj->ij", b, a) / src.shape[0])
    # Reflections are not similarities: flip the weakest direction if det(U Vt) < 0.
    sign = jnp.sign(jnp.linalg.det(U) * jnp.linalg.det(Vt))
    flip = jnp.stack([jnp.ones_like(sign), jnp.ones_like(sign), sign])
    Q = jnp.einsum("ij,j,jk->ik", U, flip, Vt)
    var = jnp.mean(jnp.sum(a * a, axis=1))
    s = jnp.where(var > 0, jnp.sum(D * flip) / jnp.where(var > 0, var, 1.0), 1.0)
    return s, Q, mu_d - s * (Q @ mu_s)


def align_rigs(rig: Rig, reference: Rig) -> Rig:
    """``rig`` moved into the frame of ``reference`` by the similarity (rotation, translation,
    scale; Umeyama on the camera centres) that best maps its centres onto the reference's.

    The whole rig is transformed (``X_ref = s Q X + c``): ``R' = R Qᵀ``, ``t' = s t − R' c``,
    ``K`` unchanged, so pixels of correspondingly transformed points do not change. Needs
    ``M ≥ 3`` centres not on one line. ``K, R (M, 3, 3)``, ``t (M, 3)``.
    """
    expect_args("align_rigs", rig=(rig, Rig), reference=(reference, Rig))
    return _align_rigs(rig, reference)


# Jitted here (as is _rig_errors) so that eager calls compile once; inlined under jit.
@jax.jit
def _align_rigs(rig: Rig, reference: Rig) -> Rig:
    s, Q, c = _similarity(rig.centers, reference.centers)
    R = jnp.einsum("mij,kj->mik", rig.R, Q)
    return Rig(rig.K, R, s * rig.t - jnp.einsum("mij,j->mi", R, c))


def rig_errors(rig: Rig, reference: Rig, *, align: bool = True) -> RigErrors:
    """Per-view errors ``(M,)`` of ``rig`` against ``reference`` (after :func:`align_rigs`
    unless ``align=False``): rotation (degrees), centre (scene units), relative focal,
    principal point (pixels). Intrinsics are compared with ``K`` normalised to ``K[2,2] = 1``."""
    expect_args("rig_errors", rig=(rig, Rig), reference=(reference, Rig))
    return _rig_errors(rig, reference, align=align)


@functools.partial(jax.jit, static_argnames="align")
def _rig_errors(rig: Rig, reference: Rig, *, align: bool) -> RigErrors:
    if align:
        rig = _align_rigs(rig, reference)
    rotation = so3_log(jnp.einsum("mij,mkj->mik", rig.R, reference.R))
    d_center = rig.centers - reference.centers
    K, K_ref = rig.K / rig.K[:, 2:3, 2:3], reference.K / reference.K[:, 2:3, 2:3]
    f, f_ref = (
        jnp.stack([K[:, 0, 0], K[:, 1, 1]], -1),
        jnp.stack([K_ref[:, 0, 0], K_ref[:, 1, 1]], -1),
    )
    d_principal = K[:, :2, 2] - K_ref[:, :2, 2]
    return RigErrors(
        rotation_deg=jnp.rad2deg(jnp.linalg.norm(rotation, axis=-1)),
        center=jnp.linalg.norm(d_center, axis=-1),
        focal_rel=jnp.max(jnp.abs(f - f_ref) / jnp.abs(f_ref), axis=-1),
        principal_px=jnp.linalg.norm(d_principal, axis=-1),
    )
