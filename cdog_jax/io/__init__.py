"""Files in and out (docs/CONVENTIONS.md §3), and rigs from and to other libraries' objects.

Rigs: EasyVis/OpenMVG folders, JSON, NPZ, anipose ``calibration.toml``, COLMAP text models,
EasyMocap ``intri.yml``/``extri.yml`` and nerfstudio ``transforms.json`` (``load_rig`` and
``save_rig``); Qualisys ``.qca.txt`` (read only); in memory, an aniposelib ``CameraGroup``, a pycolmap
``Reconstruction`` and OpenCV arrays (``rig_from_*`` / ``*_from_rig``; the libraries are
optional); exact Rodrigues and quaternion conversions.
Detections: JSON and NPZ, one scene or many frames, and converters from the encodings of
"missing" (``load_detections``, ``detections_from_lists``, ``detections_from_array``), and
a writer of the JSON form (``save_detections_json``).
Classed keypoints: OpenPose folders (``load_openpose``) and tables (``load_keypoint_table``).
Results: the groups of an :class:`cdog_jax.Association` as JSON, NPZ or CSV (with person
ids when given the result's people); marker trajectories and people's skeletons as ``.trc``
files for OpenSim and Pose2Sim (``save_trc``, ``save_people_trc``, ``load_trc``).
Every writer replaces its file atomically (``_atomic.py``); a problem with a file's
content raises :class:`InputError` (a ``ValueError``) naming the file.
"""

from ._association_files import (
    load_association_json as load_association_json,
    save_association_csv as save_association_csv,
    save_association_json as save_association_json,
    save_association_npz as save_association_npz,
)
from ._detections import (
    Detections as Detections,
    detections_from_array as detections_from_array,
    detections_from_lists as detections_from_lists,
    load_detections as load_detections,
)
from ._detections_out import save_detections_json as save_detections_json
from ._errors import InputError as InputError
from ._interop_aniposelib import (
    aniposelib_from_rig as aniposelib_from_rig,
    rig_from_aniposelib as rig_from_aniposelib,
)
from ._interop_pycolmap import (
    pycolmap_from_rig as pycolmap_from_rig,
    rig_from_pycolmap as rig_from_pycolmap,
)
from ._keypoints import (
    SKELETONS as SKELETONS,
    load_keypoint_table as load_keypoint_table,
    load_openpose as load_openpose,
)
from ._load_rig import load_rig as load_rig
from ._opencv_arrays import (
    OpenCVCameras as OpenCVCameras,
    opencv_from_rig as opencv_from_rig,
    rig_from_opencv as rig_from_opencv,
)
from ._rig_files import RigFile as RigFile
from ._rotations import (
    quaternion_from_rotation as quaternion_from_rotation,
    rodrigues_from_rotation as rodrigues_from_rotation,
    rotation_from_quaternion as rotation_from_quaternion,
    rotation_from_rodrigues as rotation_from_rodrigues,
)
from ._save_rig import save_rig as save_rig
from ._trc import (
    Trc as Trc,
    load_trc as load_trc,
    save_people_trc as save_people_trc,
    save_trc as save_trc,
)
