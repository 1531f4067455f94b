"""The physics of friction-driven mechanisms: chains, friction laws, actuators, actuation signals."""

from ._actuator import AbstractActuator as AbstractActuator, InternalForce as InternalForce, RestLength as RestLength
from ._bodies import Mechanism as Mechanism
from ._chain import Chain as Chain
from ._elements import (
    AbstractElement as AbstractElement,
    Damper as Damper,
    ExternalForce as ExternalForce,
    Force as Force,
    Spring as Spring,
    TiltedSpring as TiltedSpring,
    WALL as WALL,
)
from ._friction import (
    AbstractFriction as AbstractFriction,
    AnisotropicCoulomb as AnisotropicCoulomb,
    Coulomb as Coulomb,
    Stribeck as Stribeck,
)
from ._springwaves import SpringFourier as SpringFourier, TravellingWave as TravellingWave
