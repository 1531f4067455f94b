"""`locomotion-jax chain`: measure one chain of N masses driven by a travelling wave (SPEC §8).

`register(app)` adds the subcommand to the main CLI (`_main.py`). Per-mass and
per-spring values are comma-separated lists (one value is broadcast). Example, a
six-segment worm with backward-resisting bristles:

    locomotion-jax chain --masses 1,1,1,1,1,1 --d 0 --a 0.1 --omega 2 --phi 0.785 \\
        --friction anisotropic --mu-s 0.7 --mu-k 0.5 --mu-s-bwd 0.9 --mu-k-bwd 0.7
"""

from typing import Annotated, Literal

import numpy as np
import typer

from .._json import dumps
from ._chain_options import floats, mechanism_options, to_chain, wave_options
from ._errors import friendly
from ._options import expand, Values


def register(app: typer.Typer) -> None:
    """Add the `chain` subcommand to `app`."""

    @app.command("chain")
    @friendly
    @expand(mech=mechanism_options(), wave=wave_options())
    def chain(
        *,
        mech: Values,
        wave: Values,
        z: Annotated[float, typer.Option(help="Distance whose travel time and energy are measured.")] = 5.0,
        horizon: Annotated[float, typer.Option(help="Longest measured time after the start.")] = 2000.0,
        window: Annotated[float, typer.Option(help="Regime window after the start.")] = 25.0,
        t_start: Annotated[
            float | None, typer.Option(help="Measurement start (default: 80 periods of the lowest natural frequency).")
        ] = None,
        contact: Annotated[Literal["strict", "paper"], typer.Option(help="Contact reading.")] = "strict",
        start: Annotated[Literal["paper", "relaxed"], typer.Option(help="Initial gaps.")] = "paper",
        dt: Annotated[float, typer.Option(help="Step of the exact engine.")] = 0.01,
        as_json: Annotated[bool, typer.Option("--json", help="Print the measurements as one JSON object.")] = False,
    ) -> None:
        """Measure one chain: travel time and energy for z, speed, regime, stick fraction of each mass.

        With --json, stdout is one JSON object (non-finite numbers are null); `stick_fraction` is a list.
        """
        import locomotion_jax as lj

        try:
            m = floats("masses", mech["masses"])
            a, omega, phi = wave["a"], wave["omega"], wave["phi"]
            mech_obj = to_chain(mech, lj.TravellingWave(a, omega, phi))
            res = lj.measure(
                mech_obj, z, horizon=horizon, window=window, t_start=t_start, contact=contact, start=start,
                dynamics=lj.Exact(dt=dt),
            )  # fmt: skip
        except ValueError as err:
            typer.echo(f"Error: {err}", err=True)
            raise typer.Exit(2) from None
        fields = {}
        for name, v in res.to_numpy().items():
            v = np.asarray(v)
            fields[name] = v.tolist() if v.ndim else v.item()
        fields["regime_name"] = lj.Regime(int(res.regime)).name
        fields["status_name"] = lj.Status(int(res.status)).name
        if as_json:
            settings = dict(n_masses=len(m), friction=mech["friction"], actuator=mech["actuator"], a=a,
                            omega=omega, phi=phi, z=z, horizon=horizon, window=window, contact=contact, start=start,
                            dt=dt)  # fmt: skip
            typer.echo(dumps({**fields, **settings}))
            return
        typer.echo(f"chain of {len(m)} masses, {mech['friction']} friction, {mech['actuator']} actuator; a={a:g}, "
                   f"omega={omega:g}, phi={phi:g}")  # fmt: skip
        for name, v in fields.items():
            if isinstance(v, list):
                v = "[" + ", ".join(f"{x:.4g}" for x in v) + "]"
            typer.echo(f"  {name:<18} {v:.6g}" if isinstance(v, float) else f"  {name:<18} {v}")
