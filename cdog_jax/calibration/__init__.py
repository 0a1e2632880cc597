"""Cameras from associations, above the association methods: a joint refinement of cameras
and points (``refine_rig``), association alternated with it (``calibrate``), a similarity
alignment of rigs and their errors for evaluation, and the bundle projection error (BPE) as a
differentiable loss. Needs optimistix, a large import: ``import cdog_jax`` does not load
this package."""

from ._bpe_loss import bpe as bpe, group_bpe as group_bpe
from ._calibration import CalibrationHistory as CalibrationHistory
from ._calibration import RefineInfo as RefineInfo
from ._calibration import RigErrors as RigErrors
from ._calibration import align_rigs as align_rigs
from ._calibration import calibrate as calibrate
from ._calibration import refine_rig as refine_rig
from ._calibration import rig_errors as rig_errors
