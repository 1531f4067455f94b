"""locomotion_jax: friction-driven (stick-slip) two-mass locomotion in JAX.

The model of X. Zhou, C. Majidi, O. M. O'Reilly, "Energy efficiency in
friction-based locomotion mechanisms for soft and hard robots: slower can be
faster", Nonlinear Dynamics 78 (2014); equation numbers in docstrings are the paper's.
"""

from importlib.metadata import PackageNotFoundError, version as _version

from ._actuation import AbstractWaveform as AbstractWaveform, Fourier as Fourier, Sinusoid as Sinusoid
from ._dynamics import AbstractDynamics as AbstractDynamics, Exact as Exact, Smoothed as Smoothed
from ._measure import measure as measure
from ._params import DEFAULTS as DEFAULTS, PARAM_NAMES as PARAM_NAMES, VALID_RANGES as VALID_RANGES, Params as Params
from ._results import Measurement as Measurement, Trajectory as Trajectory
from ._simulate import simulate as simulate
from ._status import Mode as Mode, Regime as Regime, Status as Status


try:
    __version__ = _version("locomotion_jax")
except PackageNotFoundError:  # running from a source tree
    __version__ = "0.0.0+local"
