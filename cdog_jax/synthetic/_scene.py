"""Benchmark scenes (SPEC §3): uniform 3D points seen by ≥ 2 views, noisy shuffled detections."""

import equinox as eqx

from .._types import Array, Bool, Float, Int


class Scene(eqx.Module):
    """One synthetic scene with ground truth (a batch adds a leading ``B`` to every field).

    Attributes:
        xy: ``(M, P, 2)`` noisy detections (pixels); padded slots hold 0.
        mask: ``(M, P)`` bool, slot holds a detection.
        instance: ``(M, P)`` int32 ground-truth point id of each detection, -1 for padding
            (and clutter, when the generator adds it).
        points3d: ``(P, 3)`` ground-truth world point of each instance id (scene units);
            rows ``>= num_points`` are 0.
        num_points: ``()`` int32 number of instances (ids ``0 … num_points-1``).
    """

    xy: Float[Array, "M P 2"]
    mask: Bool[Array, "M P"]
    instance: Int[Array, "M P"]
    points3d: Float[Array, "P 3"]
    num_points: Int[Array, ""]
