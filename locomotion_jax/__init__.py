"""locomotion_jax: friction-driven (stick-slip) locomotion in JAX: the two-mass model and chains of N masses.

The model of X. Zhou, C. Majidi, O. M. O'Reilly, "Energy efficiency in
friction-based locomotion mechanisms for soft and hard robots: slower can be
faster", Nonlinear Dynamics 78 (2014); equation numbers in docstrings are the paper's.
"""

from importlib.metadata import PackageNotFoundError, version as _version

from ._actuation import AbstractWaveform as AbstractWaveform, Fourier as Fourier, Sinusoid as Sinusoid
from ._dynamics import AbstractDynamics as AbstractDynamics, Exact as Exact, Smoothed as Smoothed
from ._measure import measure as measure
from ._optimise import optimise as optimise
from ._optimum import OptimiseSettings as OptimiseSettings, Optimum as Optimum
from ._params import DEFAULTS as DEFAULTS, PARAM_NAMES as PARAM_NAMES, Params as Params, VALID_RANGES as VALID_RANGES
from ._pareto import best_sinusoid as best_sinusoid, pareto_front as pareto_front, sinusoid_sweep as sinusoid_sweep
from ._results import (
    ChainMeasurement as ChainMeasurement,
    ChainTrajectory as ChainTrajectory,
    Measurement as Measurement,
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


def __getattr__(name: str):
    # `animate` and `save_gif` load matplotlib's animation machinery (~0.7 s): only on first use.
    if name in ("animate", "save_gif"):
        from . import _animation

        return getattr(_animation, name)
    raise AttributeError(f"module 'locomotion_jax' has no attribute {name!r}")
