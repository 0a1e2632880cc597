"""Benchmark data (docs/BENCHMARK.md §1): the built-in rig and synthetic scenes with ground truth."""

from ._box import intrinsics_image_size as intrinsics_image_size, visible_box as visible_box
from ._realism import (
    Realism as Realism,
    perturb_rig as perturb_rig,
    student_t_mad as student_t_mad,
    unit_noise as unit_noise,
    view_sigmas as view_sigmas,
)
from ._render import (
    RealScene as RealScene,
    generate_realistic_scene as generate_realistic_scene,
    render_points as render_points,
)
from ._rig import (
    DEFAULT_BOX as DEFAULT_BOX,
    IMAGE_SIZE as IMAGE_SIZE,
    default_rig as default_rig,
    look_at_rotation as look_at_rotation,
    negate_intrinsics as negate_intrinsics,
)
from ._ring import RING_IMAGE_SIZE as RING_IMAGE_SIZE, ring_rig as ring_rig
from ._scene import (
    Scene as Scene,
    generate_scene as generate_scene,
    generate_scenes as generate_scenes,
)
from ._skeleton import (
    SKELETON_BONES as SKELETON_BONES,
    SKELETON_JOINTS as SKELETON_JOINTS,
    SKELETON_TEMPLATE as SKELETON_TEMPLATE,
    SkeletonScenes as SkeletonScenes,
    generate_skeleton_scenes as generate_skeleton_scenes,
    skeleton_motion as skeleton_motion,
)
