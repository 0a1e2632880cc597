"""Readers and writers of rig files (SPEC §4): EasyVis/OpenMVG folders, JSON and NPZ."""

from ._rig_files import RigFile as RigFile
from ._rig_files import load_rig as load_rig
from ._rig_files import save_rig_easyvis as save_rig_easyvis
from ._rig_files import save_rig_json as save_rig_json
from ._rig_files import save_rig_npz as save_rig_npz
