"""`locomotion-jax chain`: measure one chain of N masses driven by a travelling wave (SPEC §8).

`register(app)` adds the subcommand to the main CLI (`_main.py`). Per-mass and
per-spring values are comma-separated lists (one value is broadcast). Example, a
six-segment worm with backward-resisting bristles:

    locomotion-jax chain --masses 1,1,1,1,1,1 --d 0 --a 0.1 --omega 2 --phi 0.785 \\
        --friction anisotropic --mu-s 0.7 --mu-k 0.5 --mu-s-bwd 0.9 --mu-k-bwd 0.7
"""

import math
from typing import Annotated, Literal

import numpy as np
import typer

from .._json import dumps


def _floats(name: str, text: str) -> list[float]:
    try:
        values = [float(v) for v in text.split(",") if v.strip()]
    except ValueError:
        raise ValueError(f"--{name} must be a number or a comma-separated list of numbers, got {text!r}.") from None
    if not values:
        raise ValueError(f"--{name} is empty.")
    return values


def _one(values: list[float]) -> float | list[float]:
    return values[0] if len(values) == 1 else values


def register(app: typer.Typer) -> None:
    """Add the `chain` subcommand to `app`."""

    @app.command("chain")
    def chain(
        masses: Annotated[str, typer.Option(help="Masses m_i, comma-separated (N >= 2; the total sets the scale).")],
        k: Annotated[str, typer.Option(help="Stiffness per spring (one value or N-1).")] = "50",
        d: Annotated[str, typer.Option(help="Vertical offset per spring.")] = "0.5",
        lbar: Annotated[str, typer.Option(help="Mean rest length per spring.")] = "3",
        c: Annotated[str, typer.Option(help="Damping per mass.")] = "0.01",
        a: Annotated[float, typer.Option(help="Amplitude of the travelling wave s_j = a sin(omega t - j phi).")] = 0.05,
        omega: Annotated[float, typer.Option(help="Frequency of the wave.")] = 2.0,
        phi: Annotated[float, typer.Option(help="Phase lag between neighbouring springs (> 0: towards +x).")] = 0.0,
        actuator: Annotated[
            Literal["length", "force"], typer.Option(help="The signal is a rest length or an internal force.")
        ] = "length",
        friction: Annotated[
            Literal["coulomb", "anisotropic", "stribeck"], typer.Option(help="Friction law of every mass.")
        ] = "coulomb",
        mu_s: Annotated[str, typer.Option(help="Static coefficient (forward where anisotropic), per mass.")] = "0.7",
        mu_k: Annotated[str, typer.Option(help="Kinetic coefficient (forward where anisotropic), per mass.")] = "0.5",
        mu_s_bwd: Annotated[str | None, typer.Option(help="Backward static coefficient (default: forward).")] = None,
        mu_k_bwd: Annotated[str | None, typer.Option(help="Backward kinetic coefficient (default: forward).")] = None,
        v_s: Annotated[float, typer.Option(help="Stribeck speed (friction=stribeck).")] = 0.3,
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
            m = _floats("masses", masses)
            law = {"mu_s": _floats("mu-s", mu_s), "mu_k": _floats("mu-k", mu_k)}
            bwd = {
                "mu_s_bwd": law["mu_s"] if mu_s_bwd is None else _floats("mu-s-bwd", mu_s_bwd),
                "mu_k_bwd": law["mu_k"] if mu_k_bwd is None else _floats("mu-k-bwd", mu_k_bwd),
            }
            if friction == "coulomb":
                if mu_s_bwd is not None or mu_k_bwd is not None:
                    raise ValueError("--mu-s-bwd/--mu-k-bwd need --friction anisotropic or stribeck.")
                law_obj = lj.Coulomb(_one(law["mu_s"]), _one(law["mu_k"]))
            elif friction == "anisotropic":
                law_obj = lj.AnisotropicCoulomb(
                    _one(law["mu_s"]), _one(bwd["mu_s_bwd"]), _one(law["mu_k"]), _one(bwd["mu_k_bwd"])
                )
            else:
                if not (math.isfinite(v_s) and v_s > 0):
                    raise ValueError(f"--v-s must be a finite number > 0, got {v_s!r}.")
                law_obj = lj.Stribeck(
                    _one(law["mu_s"]), _one(law["mu_k"]), v_s, mu_s_bwd=_one(bwd["mu_s_bwd"]),
                    mu_k_bwd=_one(bwd["mu_k_bwd"]),
                )  # fmt: skip
            mech = lj.Chain(
                masses=m, k=_one(_floats("k", k)), d=_one(_floats("d", d)), lbar=_one(_floats("lbar", lbar)),
                c=_one(_floats("c", c)), waveforms=lj.TravellingWave(a, omega, phi), friction=law_obj,
                actuator=lj.InternalForce() if actuator == "force" else lj.RestLength(),
            )  # fmt: skip
            res = lj.measure(
                mech, z, horizon=horizon, window=window, t_start=t_start, contact=contact, start=start,
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
            settings = dict(n_masses=len(m), friction=friction, actuator=actuator, a=a, omega=omega, phi=phi, z=z,
                            horizon=horizon, window=window, contact=contact, start=start, dt=dt)  # fmt: skip
            typer.echo(dumps({**fields, **settings}))
            return
        typer.echo(f"chain of {len(m)} masses, {friction} friction, {actuator} actuator; a={a:g}, omega={omega:g}, "
                   f"phi={phi:g}")  # fmt: skip
        for name, v in fields.items():
            if isinstance(v, list):
                v = "[" + ", ".join(f"{x:.4g}" for x in v) + "]"
            typer.echo(f"  {name:<18} {v:.6g}" if isinstance(v, float) else f"  {name:<18} {v}")
