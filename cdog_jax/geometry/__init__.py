"""Cameras, lens distortion, epipolar geometry, triangulation (docs/CONVENTIONS.md, docs/ALGORITHM.md §1–2), a rig
summary with sanity warnings (``describe_rig``), and a camera parameterisation
for optimisation (axis-angle rotations, intrinsics)."""

from ._camera import (
    Rig as Rig,
    camera_points as camera_points,
    in_front as in_front,
    rig_from_arrays as rig_from_arrays,
)
from ._describe import RigDescription as RigDescription, describe_rig as describe_rig
from ._distortion import (
    Fisheye as Fisheye,
    distort_pixels as distort_pixels,
    undistort_pixels as undistort_pixels,
)
from ._epipolar import (
    epipolar_distances as epipolar_distances,
    essential_from_rig as essential_from_rig,
    fundamental_from_rig as fundamental_from_rig,
)
from ._parameters import (
    CameraParams as CameraParams,
    params_from_rig as params_from_rig,
    rig_from_params as rig_from_params,
)
from ._projection import project as project, reprojection_errors as reprojection_errors
from ._triangulate import dlt_blocks as dlt_blocks, triangulate as triangulate
