"""locomotion_jax: friction-driven (stick-slip) locomotion in JAX: the two-mass model and chains of N masses.

The model of X. Zhou, C. Majidi, O. M. O'Reilly, "Energy efficiency in
friction-based locomotion mechanisms for soft and hard robots: slower can be
faster", Nonlinear Dynamics 78 (2014); equation numbers in docstrings are the paper's.
"""

from importlib.metadata import PackageNotFoundError, version as _version

from ._actuation import (
    AbstractWaveform as AbstractWaveform,
    Fourier as Fourier,
    Sinusoid as Sinusoid,
    Spline as Spline,
)
from ._basins import Basins as Basins, basins as basins
from ._bifurcation import BranchEvents as BranchEvents, EventKind as EventKind
from ._cache import enable_compilation_cache as enable_compilation_cache
from ._chain_gait import ChainGait as ChainGait
from ._continuation import Branch as Branch, BranchStatus as BranchStatus, continuation as continuation
from ._dynamics import AbstractDynamics as AbstractDynamics, Exact as Exact, Smoothed as Smoothed
from ._gait import Gait as Gait, GaitStatus as GaitStatus, steady_gait as steady_gait
from ._measure import measure as measure
from ._optimum import (
    ExactOptimiseSettings as ExactOptimiseSettings,
    OptimiseSettings as OptimiseSettings,
    Optimum as Optimum,
)
from ._params import DEFAULTS as DEFAULTS, PARAM_NAMES as PARAM_NAMES, Params as Params, VALID_RANGES as VALID_RANGES
from ._results import (
    ChainMeasurement as ChainMeasurement,
    ChainTrajectory as ChainTrajectory,
    Measurement as Measurement,
    SMOOTH_MARGIN as SMOOTH_MARGIN,
    SMOOTH_MARGIN_Z as SMOOTH_MARGIN_Z,
    Trajectory as Trajectory,
)
from ._simulate import simulate as simulate
from ._status import Mode as Mode, Regime as Regime, Status as Status
from ._sweep import sweep as sweep
from .model import (
    AbstractActuator as AbstractActuator,
    AbstractFriction as AbstractFriction,
    AnisotropicCoulomb as AnisotropicCoulomb,
    Chain as Chain,
    Coulomb as Coulomb,
    InternalForce as InternalForce,
    RestLength as RestLength,
    SpringFourier as SpringFourier,
    Stribeck as Stribeck,
    TravellingWave as TravellingWave,
)


try:
    __version__ = _version("locomotion_jax")
except PackageNotFoundError:  # running from a source tree
    __version__ = "0.0.0+local"


_LAZY = {
    # matplotlib's animation machinery (~0.7 s)
    "animate": "_animation",
    "save_gif": "_animation",
    # optax and the optimiser (~0.15 s), which a simulation or a sweep does not need
    "optimise": "_optimise",
    "optimize": "_optimise",
    "best_sinusoid": "_pareto",
    "pareto_front": "_pareto",
    "sinusoid_sweep": "_pareto",
    # scipy's least squares, for parameter identification
    "fit_trajectory": "_fit",
    "FitResult": "_fit",
}
"""Public names imported on first use, so that `import locomotion_jax` stays quick."""


def __getattr__(name: str):
    if name in _LAZY:
        from importlib import import_module

        return getattr(import_module(f".{_LAZY[name]}", __name__), name)
    raise AttributeError(f"module 'locomotion_jax' has no attribute {name!r}")


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(_LAZY))
