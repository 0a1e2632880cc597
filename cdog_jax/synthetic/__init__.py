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
