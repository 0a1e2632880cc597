"""cdog_jax: multi-view, multi-instance point association with connected δ-overlap graphs."""

from ._associate import associate as associate, associate_batch as associate_batch
from ._method import (
    GroupTableMethod as GroupTableMethod,
    Method as Method,
    Observations as Observations,
    method_from as method_from,
    method_names as method_names,
    register_method as register_method,
    unregister_method as unregister_method,
)
from ._result import Association as Association

# Importing the package changes no JAX setting: the command line turns the persistent
# compilation cache on, a script or notebook calls this.
from ._runtime.compile_cache import enable_compilation_cache as enable_compilation_cache

# The figures load on first use: `import cdog_jax` reads neither the plotting modules nor
# the file formats they write through.
from ._runtime.lazy_names import load_on_first_use as _load_on_first_use
from ._runtime.memory import estimate_peak_bytes as estimate_peak_bytes
from ._status import (
    Status as Status,
    check_status as check_status,
    status_messages as status_messages,
)
from ._version import __version__ as __version__
from .cdog._pipeline import (
    STAGES as STAGES,
    Config as Config,
    Thresholds as Thresholds,
    associate_traced as associate_traced,
)
from .geometry import (
    Rig as Rig,
    project as project,
    rig_from_arrays as rig_from_arrays,
    triangulate as triangulate,
)
from .people._classes import (
    ClassAssociation as ClassAssociation,
    associate_classes as associate_classes,
    class_sigmas as class_sigmas,
)
from .people._persons import (
    People as People,
    PersonVote as PersonVote,
    identify_people as identify_people,
)
from .tracking._live import LiveAssociator as LiveAssociator, LiveFrame as LiveFrame
from .tracking._sequence import associate_sequence as associate_sequence
from .tracking._tracks import TrackedAssociation as TrackedAssociation, track_groups as track_groups

# isort: split
# After C-DOG's presets, so that the registry lists them first.
from . import baselines as baselines  # registers the baseline methods

_FIGURES = ("plot_association", "plot_bpe_histogram", "plot_epipolar", "plot_rays", "plot_rig")
__getattr__, __dir__, __all__ = _load_on_first_use(globals(), dict.fromkeys(_FIGURES, ".viz"))
