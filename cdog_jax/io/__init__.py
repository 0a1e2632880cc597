"""Files in and out (SPEC §4).

Rigs: EasyVis/OpenMVG folders, JSON, NPZ, anipose ``calibration.toml``, COLMAP text models
and EasyMocap ``intri.yml``/``extri.yml`` (``load_rig`` and the ``save_rig_*`` writers);
Qualisys ``.qca.txt`` (read only).
Detections: JSON and NPZ, one scene or many frames, and converters from the encodings of
"missing" (``load_detections``, ``detections_from_lists``, ``detections_from_array``);
classed keypoints: OpenPose folders (``load_openpose``) and tables (``load_keypoint_table``).
Results: the groups of an :class:`cdog_jax.Association` as JSON, NPZ or CSV.
Every writer replaces its file atomically (``_atomic.py``); a problem with a file's
content raises :class:`InputError` (a ``ValueError``) naming the file.
"""

from ._anipose import save_rig_anipose as save_rig_anipose
from ._association_files import association_records as association_records
from ._association_files import load_association_json as load_association_json
from ._association_files import save_association_csv as save_association_csv
from ._association_files import save_association_json as save_association_json
from ._association_files import save_association_npz as save_association_npz
from ._colmap import save_rig_colmap as save_rig_colmap
from ._detections import Detections as Detections
from ._detections import detections_from_array as detections_from_array
from ._detections import detections_from_lists as detections_from_lists
from ._detections import load_detections as load_detections
from ._easymocap import save_rig_easymocap as save_rig_easymocap
from ._keypoints import SKELETONS as SKELETONS
from ._keypoints import load_keypoint_table as load_keypoint_table
from ._keypoints import load_openpose as load_openpose
from ._errors import InputError as InputError
from ._rig_files import FORMATS as FORMATS
from ._rig_files import RigFile as RigFile
from ._rig_files import load_rig as load_rig
from ._rig_files import save_rig_easyvis as save_rig_easyvis
from ._rig_files import save_rig_json as save_rig_json
from ._rig_files import save_rig_npz as save_rig_npz
