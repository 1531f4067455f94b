"""A sweep's results as an `xarray.Dataset`: one variable per `Measurement` field, its settings as attributes."""

from typing import Any

import jax
import numpy as np

from .._results import MEASUREMENT_PAPER_KEYS
from .._status import Regime, Status
from ..dynamics._base import AbstractDynamics
from ._grid import Grid


MEASURE_FIELDS: tuple[str, ...] = tuple(
    f for f in MEASUREMENT_PAPER_KEYS if f not in ("flight_fraction", "landings_per_period", "highest_hop", "zeno")
)
"""The dataset's variables under every contact reading: every array of a [`Measurement`][] of the
paper's model that every reading has, named as its `to_numpy` names them (`stick_fraction1`,
`stick_fraction2`; the hopping fields, `None` outside `contact="hop"`, are [`HOP_FIELDS`][])."""

HOP_FIELDS: tuple[str, ...] = (
    "flight_fraction1",
    "flight_fraction2",
    "highest_hop1",
    "highest_hop2",
    "landings_per_period",
    "zeno",
)
"""The dataset's extra variables under `contact="hop"` (SPEC §10): `Measurement`'s hopping fields, the
per-mass ones (`flight_fraction`, `highest_hop`, a trailing axis of 2) as one variable per mass, as
`stick_fraction1`, `stick_fraction2` are, so that every variable has the grid's dimensions."""

_PER_MASS: tuple[str, ...] = ("flight_fraction", "highest_hop")


def dataset_fields(contact: str) -> tuple[str, ...]:
    """The variables of a sweep's dataset under `contact`: [`MEASURE_FIELDS`][], and [`HOP_FIELDS`][]
    under `"hop"` (a strict or paper sweep's dataset has no hopping variable)."""
    return MEASURE_FIELDS + (HOP_FIELDS if contact == "hop" else ())


def per_mass_columns(out: dict) -> dict:
    """A chunk's measurements with each per-mass field (`stick_fraction`, and the hopping ones
    `flight_fraction`, `highest_hop`; shape `(n, 2)`) split into one field per mass
    (`stick_fraction1`, `stick_fraction2`, `flight_fraction1`, ...)."""
    out = dict(out)
    for name in ("stick_fraction",) + _PER_MASS:
        if name in out:
            both = out.pop(name)
            out |= {f"{name}1": both[..., 0], f"{name}2": both[..., 1]}
    return out


DESCRIPTIONS = {
    "tau_z": "time to travel z after t_start (inf: not reached)",
    "e_z": "energy dissipated while travelling z, eq. (15) (inf: not reached)",
    "reached": "|X - X(t_start)| reached z within the horizon",
    "regime": "1 SSL (stick-slip), 0 SL (slip), -1 undetermined",
    "mean_speed": "signed mean speed of the centre of mass over the measured interval",
    "cost_of_transport": "e_z / z",
    "stick_fraction1": "fraction of the regime window mass 1 is stuck",
    "stick_fraction2": "fraction of the regime window mass 2 is stuck",
    "e_d": "dissipated energy over the measured interval, eq. (15)",
    "work": "actuator work over the measured interval, eq. (16)",
    "delta_e": "change of total energy over the measured interval, eq. (10)",
    "balance": "work - e_d - delta_e (zero up to integration error)",
    "liftoff": "a normal force reached zero, eq. (5)",
    "t_liftoff": "first lift-off time (inf: none)",
    "status": ", ".join(f"{int(s)} {s.name}" for s in Status),
    "t_start": "start of the measurement: 80 periods of the lowest natural frequency",
    "X_start": "centre of mass at t_start, eq. (4)",
    "n_steps": "integrator iterations",
    "n_switch": "contact-mode switches",
    "transversality": "smallest margin (rad of drive phase) at a located switch in the measured interval",
    "near_miss": "smallest margin (rad of drive phase) at a near miss of an event function",
    "margin_z": "margin (rad of drive phase) of the target |X - X0| = z: its crossing, near misses, nearest switch",
    "omega": "actuation frequency derived from omega_over_wn1",
    "flight_fraction1": "fraction of the regime window mass 1 is in flight (contact='hop')",
    "flight_fraction2": "fraction of the regime window mass 2 is in flight (contact='hop')",
    "highest_hop1": "greatest height of mass 1 during the run (0: never flew; contact='hop')",
    "highest_hop2": "greatest height of mass 2 during the run (0: never flew; contact='hop')",
    "landings_per_period": "landings of both masses per actuation period 2 pi / omega over the regime window "
    "(contact='hop')",
    "zeno": "the Zeno rule made a rebound plastic during the run (contact='hop')",
}


def sweep_attrs(grid: Grid, spec: dict, dynamics: AbstractDynamics, max_steps: int, n_devices: int, order: str) -> dict:
    from .. import __version__
    from ._store import canonical

    attrs: dict[str, Any] = {
        "title": "locomotion_jax parameter sweep (Zhou, Majidi, O'Reilly 2014)",
        "sweep_mode": grid.mode,
        "swept": ",".join(grid.names),
    }
    attrs.update({f"fixed_{n}": v for n, v in grid.fixed.items()})
    attrs.update({f"dynamics_{k}" if k != "dynamics" else "dynamics": v for k, v in dynamics.describe().items()})
    attrs.update(
        max_steps=max_steps,
        dtype=spec["dtype"],
        contact=spec["contact"],
        start=spec["start"],
        z=spec["z"],
        horizon=spec["horizon"],
        window=spec["window"],
        on_invalid=spec["on_invalid"],
        order=order,
        version=__version__,
        jax_version=jax.__version__,
        n_devices=n_devices,
        status_codes=", ".join(f"{int(s)}={s.name}" for s in Status),
        regime_codes=", ".join(f"{int(r)}={r.name}" for r in Regime),
        sweep_spec=canonical(spec),
    )
    return attrs


def to_dataset(grid: Grid, results: dict[str, np.ndarray], attrs: dict):
    import xarray as xr

    dims = grid.names if grid.mode == "grid" else ("config",)
    coords = {n: (n if grid.mode == "grid" else "config", grid.values[n]) for n in grid.names}
    data = {k: (dims, v.reshape(grid.shape), {"description": DESCRIPTIONS.get(k, k)}) for k, v in results.items()}
    return xr.Dataset(data, coords=coords, attrs=attrs)
