"""Readers and writers of rig files (SPEC §4): EasyVis/OpenMVG folders, JSON, NPZ, anipose
``calibration.toml``, COLMAP text models and EasyMocap ``intri.yml``/``extri.yml``."""

from ._anipose import save_rig_anipose as save_rig_anipose
from ._colmap import save_rig_colmap as save_rig_colmap
from ._easymocap import save_rig_easymocap as save_rig_easymocap
from ._rig_files import FORMATS as FORMATS
from ._rig_files import RigFile as RigFile
from ._rig_files import load_rig as load_rig
from ._rig_files import save_rig_easyvis as save_rig_easyvis
from ._rig_files import save_rig_json as save_rig_json
from ._rig_files import save_rig_npz as save_rig_npz
