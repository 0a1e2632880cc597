"""Benchmark data (docs/BENCHMARK.md §1): the built-in rig and synthetic scenes with ground truth."""

from ._box import visible_box as visible_box
from ._realism import Realism as Realism, perturb_rig as perturb_rig
from ._render import RealScene as RealScene, generate_realistic_scene as generate_realistic_scene
from ._rig import DEFAULT_BOX as DEFAULT_BOX, IMAGE_SIZE as IMAGE_SIZE, default_rig as default_rig
from ._ring import ring_rig as ring_rig
from ._scene import (
    Scene as Scene,
    generate_scene as generate_scene,
    generate_scenes as generate_scenes,
)
from ._skeleton import (
    SKELETON_JOINTS as SKELETON_JOINTS,
    KeypointErrors as KeypointErrors,
    SkeletonScenes as SkeletonScenes,
    generate_skeleton_scenes as generate_skeleton_scenes,
)
