"""Benchmark data (docs/BENCHMARK.md §1): the built-in rig and synthetic scenes with ground truth."""

from ._rig import DEFAULT_BOX as DEFAULT_BOX
from ._rig import IMAGE_SIZE as IMAGE_SIZE
from ._rig import default_rig as default_rig
from ._rig import look_at_rotation as look_at_rotation
from ._rig import negate_intrinsics as negate_intrinsics
from ._scene import Scene as Scene
from ._scene import generate_scene as generate_scene
from ._scene import generate_scenes as generate_scenes
from ._box import intrinsics_image_size as intrinsics_image_size
from ._box import visible_box as visible_box
from ._realism import Realism as Realism
from ._realism import perturb_rig as perturb_rig
from ._realism import student_t_mad as student_t_mad
from ._realism import unit_noise as unit_noise
from ._realism import view_sigmas as view_sigmas
from ._render import RealScene as RealScene
from ._render import generate_realistic_scene as generate_realistic_scene
from ._render import render_points as render_points
from ._ring import RING_IMAGE_SIZE as RING_IMAGE_SIZE
from ._ring import ring_rig as ring_rig
from ._skeleton import SKELETON_BONES as SKELETON_BONES
from ._skeleton import SKELETON_JOINTS as SKELETON_JOINTS
from ._skeleton import SKELETON_TEMPLATE as SKELETON_TEMPLATE
from ._skeleton import SkeletonScenes as SkeletonScenes
from ._skeleton import generate_skeleton_scenes as generate_skeleton_scenes
from ._skeleton import skeleton_motion as skeleton_motion
