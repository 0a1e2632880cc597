"""Scene boxes for user rigs (docs/BENCHMARK.md §1): the image size implied by K, and an axis-aligned box
of the region that several cameras see, to pass to ``generate_scene(box=…)``.

Host-side helpers (NumPy plus eager JAX projection), not part of the jitted pipeline.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np

from .._expect import ARRAY, expect_args
from .._types import Array, Float
from ..geometry._camera import Rig
from ..geometry._projection import project

_project_points = jax.jit(jax.vmap(project, in_axes=(None, 0)))  # (S, 3) → (S, M, 2), (S, M)

_MIN_VISIBLE_FRACTION = 0.01


def intrinsics_image_size(
    K: Float[Array, "*M 3 3"] | np.ndarray, *, multiple: int = 8
) -> tuple[int, int]:
    """Best-guess image ``(width, height)`` in pixels from intrinsics ``K (3, 3)`` or
    ``(M, 3, 3)``, for rig files that give no image size.

    Assumes the principal point is near the image centre: the median over views of
    ``(2 cx, 2 cy)`` of ``K / K[2,2]`` (so ``K[2,2] = -1`` is fine), rounded to the nearest
    multiple of ``multiple`` (sensor sizes nearly always are multiples of 8, while
    calibrated principal points scatter by several pixels; ``multiple=1`` rounds plainly).
    For the built-in rig this gives ``IMAGE_SIZE = (640, 480)``. Raises ``ValueError`` if
    the guess is not positive (a principal point far from the image centre).
    """
    expect_args("intrinsics_image_size", K=(K, ARRAY))
    if not isinstance(multiple, int) or multiple < 1:
        raise ValueError(f"multiple must be a Python int >= 1; got {multiple!r}")
    K = np.asarray(K, dtype=np.float64)
    if K.shape[-2:] != (3, 3) or K.ndim not in (2, 3):
        raise ValueError(f"K must have shape (3, 3) or (M, 3, 3); got {K.shape}")
    K = K.reshape(-1, 3, 3)
    if K.shape[0] == 0 or np.any(K[:, 2, 2] == 0) or not np.isfinite(K).all():
        raise ValueError("K must be finite with K[2,2] != 0 in every view")
    centre = K[:, :2, 2] / K[:, 2:3, 2]  # (M, 2) principal points in pixels
    size = np.median(2.0 * centre, axis=0)
    width, height = (int(multiple * np.round(s / multiple)) for s in size)
    if width < 1 or height < 1:
        raise ValueError(
            f"cannot guess the image size: principal point (median) {np.median(centre, axis=0).tolist()} "
            "is not inside a plausible image; pass the image size explicitly"
        )
    return width, height


def visible_box(
    rig: Rig,
    image_size: tuple[int, int],
    *,
    min_views: int = 2,
    samples: int = 20000,
    seed: int = 0,
    quantile: float = 0.02,
) -> np.ndarray:
    """An axis-aligned box ``(2, 3)`` (lower, upper corner; scene units) of the region seen by
    at least ``min_views`` cameras, for ``generate_scene(rig, …, box=visible_box(rig, size))``.

    The centre is the point closest, in least squares, to the optical axes of all cameras;
    the search cube around it has half-size the median camera-to-centre distance (the
    region two cameras share is an unbounded cone intersection, so the cube is what keeps
    the box to the working volume; it may cut the region, e.g. below a floor the cameras
    look down on).
    ``samples`` uniform points of the cube are kept when in front of and inside the image
    (``[0, w) × [0, h)``, as ``generate_scene``) of ≥ ``min_views`` views; a second draw of
    ``samples`` points in the bounding box of the kept ones sharpens the estimate. The box is
    the per-axis ``[quantile, 1 - quantile]`` quantiles of the kept points of that draw.

    Args:
        rig: ``M`` cameras, ``K, R (M, 3, 3)``, ``t (M, 3)`` (general ``K``).
        image_size: ``(width, height)`` in pixels (see :func:`intrinsics_image_size`).
        min_views: views that must see a point.
        samples: points per draw.
        seed: NumPy seed; the box is deterministic for a given seed.
        quantile: trimmed from each end of each axis, in ``[0, 0.5)``.

    Returns:
        ``(2, 3)`` float64 NumPy array. Raises ``ValueError`` when fewer than 1 % of the
        search cube's points are seen by ``min_views`` views (cameras with no common region).
    """
    expect_args("visible_box", rig=(rig, Rig), image_size=(image_size, (tuple, list)))
    M = rig.K.shape[0] if rig.K.ndim == 3 else -1
    if M < 1:
        raise ValueError(f"visible_box takes one rig with K of shape (M, 3, 3); got {rig.K.shape}")
    if not isinstance(min_views, int) or not 1 <= min_views <= M:
        raise ValueError(f"min_views must be an int in [1, M={M}]; got {min_views!r}")
    if not isinstance(samples, int) or samples < 100:
        raise ValueError(f"samples must be an int >= 100; got {samples!r}")
    if not 0.0 <= quantile < 0.5:
        raise ValueError(f"quantile must be in [0, 0.5); got {quantile!r}")
    if len(image_size) != 2:
        raise ValueError(f"image_size must be (width, height); got {image_size!r}")
    rng = np.random.default_rng(seed)

    centers = np.asarray(rig.centers, dtype=np.float64)  # (M, 3)
    dirs = np.asarray(rig.view_dirs, dtype=np.float64)
    dirs = dirs / np.linalg.norm(dirs, axis=-1, keepdims=True)
    # Σ (I - d dᵀ)(X - C) = 0; lstsq copes with parallel axes (a rank-deficient system).
    proj_perp = np.eye(3)[None] - np.einsum("mi,mj->mij", dirs, dirs)  # (M, 3, 3)
    A = proj_perp.sum(axis=0)
    b = np.einsum("mij,mj->i", proj_perp, centers)
    centre = np.linalg.lstsq(A, b, rcond=None)[0]
    half = float(np.median(np.linalg.norm(centers - centre, axis=-1)))
    if not half > 0:
        raise ValueError(
            "cannot build a search region: all camera centres coincide with the axes' closest point"
        )

    lo, hi = centre - half, centre + half
    kept = _seen(rig, rng.uniform(lo, hi, size=(samples, 3)), image_size, min_views)
    if len(kept) < _MIN_VISIBLE_FRACTION * samples:
        raise ValueError(
            f"only {len(kept)} of {samples} points around the cameras' common focus are seen by "
            f">= {min_views} views (need 1 %); do the cameras look at a common region?"
        )
    # Resample in the bounding box of what was seen: same distribution, more points kept.
    lo, hi = kept.min(axis=0), kept.max(axis=0)
    kept = _seen(rig, rng.uniform(lo, hi, size=(samples, 3)), image_size, min_views)
    return np.quantile(kept, [quantile, 1.0 - quantile], axis=0)


def _seen(rig: Rig, X: np.ndarray, image_size: tuple[int, int], min_views: int) -> np.ndarray:
    """The rows of ``X (S, 3)`` in front of and inside the image of ≥ ``min_views`` views."""
    xy, front = _project_points(rig, jnp.asarray(X, dtype=rig.K.dtype))
    xy, front = np.asarray(xy), np.asarray(front)
    w, h = image_size
    x, y = xy[..., 0], xy[..., 1]
    visible = front & (x >= 0) & (x < w) & (y >= 0) & (y < h)  # (S, M)
    return X[visible.sum(axis=-1) >= min_views]
