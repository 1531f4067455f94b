"""locomotion_jax: friction-driven (stick-slip) locomotion in JAX: the two-mass model and chains of N masses.

The model of X. Zhou, C. Majidi, O. M. O'Reilly, "Energy efficiency in
friction-based locomotion mechanisms for soft and hard robots: slower can be
faster", Nonlinear Dynamics 78 (2014); equation numbers in docstrings are the paper's.
"""

from importlib.metadata import PackageNotFoundError, version as _version

from ._cache import enable_compilation_cache as enable_compilation_cache
from ._results import (
    Measurement as Measurement,
    SMOOTH_MARGIN as SMOOTH_MARGIN,
    SMOOTH_MARGIN_Z as SMOOTH_MARGIN_Z,
    Trajectory as Trajectory,
)
from ._status import Mode as Mode, Regime as Regime, Status as Status
from .dynamics._base import AbstractDynamics as AbstractDynamics
from .dynamics._exact_dynamics import Exact as Exact
from .dynamics._smoothed_dynamics import Smoothed as Smoothed
from .gaits._basins import Basins as Basins, basins as basins
from .gaits._bifurcation import BranchEvents as BranchEvents, EventKind as EventKind
from .gaits._continuation import Branch as Branch, BranchStatus as BranchStatus, continuation as continuation
from .gaits._gait import Gait as Gait, GaitStatus as GaitStatus, steady_gait as steady_gait
from .maps._sweep import sweep as sweep
from .model import (
    AbstractActuator as AbstractActuator,
    AbstractElement as AbstractElement,
    AbstractFriction as AbstractFriction,
    AnisotropicCoulomb as AnisotropicCoulomb,
    Chain as Chain,
    Coulomb as Coulomb,
    Damper as Damper,
    ExternalForce as ExternalForce,
    Force as Force,
    InternalForce as InternalForce,
    Mechanism as Mechanism,
    RestLength as RestLength,
    Spring as Spring,
    SpringFourier as SpringFourier,
    Stribeck as Stribeck,
    TiltedSpring as TiltedSpring,
    TravellingWave as TravellingWave,
    WALL as WALL,
)
from .model._files import load_mechanism as load_mechanism, MechanismFileError as MechanismFileError
from .model._files_save import save_mechanism as save_mechanism
from .model._params import (
    DEFAULTS as DEFAULTS,
    PARAM_NAMES as PARAM_NAMES,
    Params as Params,
    VALID_RANGES as VALID_RANGES,
)
from .model._physics import AbstractPhysics as AbstractPhysics, LoadRates as LoadRates, Loads as Loads
from .model._waveform import (
    AbstractWaveform as AbstractWaveform,
    Fourier as Fourier,
    Sinusoid as Sinusoid,
    Spline as Spline,
)
from .optimisation._element_optimum import (
    ChainOptimiseSettings as ChainOptimiseSettings,
    ChainOptimum as ChainOptimum,
    MechanismOptimiseSettings as MechanismOptimiseSettings,
    MechanismOptimum as MechanismOptimum,
)
from .optimisation._optimum import (
    ExactOptimiseSettings as ExactOptimiseSettings,
    OptimiseSettings as OptimiseSettings,
    Optimum as Optimum,
)
from .run._measure import measure as measure
from .run._simulate import simulate as simulate


try:
    __version__ = _version("locomotion_jax")
except PackageNotFoundError:  # running from a source tree
    __version__ = "0.0.0+local"


_LAZY = {
    # matplotlib's animation machinery (~0.7 s)
    "animate": "run._animation",
    "save_gif": "run._animation",
    # optax and the optimiser (~0.15 s), which a simulation or a sweep does not need
    "optimise": "optimisation._optimise",
    "optimize": "optimisation._optimise",
    "best_sinusoid": "optimisation._pareto",
    "pareto_front": "optimisation._pareto",
    "sinusoid_sweep": "optimisation._pareto",
    # scipy's least squares, for parameter identification
    "fit_trajectory": "optimisation._fit",
    "FitResult": "optimisation._fit",
}
"""Public names imported on first use, so that `import locomotion_jax` stays quick."""


_DEPRECATED = {"ChainTrajectory": "Trajectory", "ChainMeasurement": "Measurement", "ChainGait": "Gait"}
"""Deprecated names (for one release) and the classes they name: one `Trajectory`, one
`Measurement` and one `Gait` serve every mechanism."""


def __getattr__(name: str):
    if name in _DEPRECATED:
        import warnings

        new = _DEPRECATED[name]
        warnings.warn(f"locomotion_jax.{name} is deprecated: use locomotion_jax.{new}.", DeprecationWarning, 2)
        return globals()[new]
    if name in _LAZY:
        from importlib import import_module

        return getattr(import_module(f".{_LAZY[name]}", __name__), name)
    raise AttributeError(f"module 'locomotion_jax' has no attribute {name!r}")


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(_LAZY))
