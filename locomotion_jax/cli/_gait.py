"""`locomotion-jax gait` and `locomotion-jax continue`: steady gaits from the command line.

Both run any mechanism (`_mechanism.build`): the paper's model, a chain, a mechanism file.

`register(app)` adds both subcommands to the main CLI (`_main.py`). `gait` solves the steady gait of
one configuration ([`steady_gait`][]); `continue` follows it along one parameter ([`continuation`][]).
With `--json` stdout is one JSON object; every non-finite number is `null` (`_json.py`), and a complex
Floquet multiplier is a pair `[re, im]`.
"""

import math
from pathlib import Path
from typing import Annotated, Any, NoReturn

import numpy as np
import typer

from .._json import dumps
from .._results import PAPER
from ._errors import friendly
from ._mechanism import build, mechanism_options, number
from ._options import expand, run_options, Values


GAIT_FIELDS: tuple[str, ...] = (
    "k", "period", "mean_speed", "cost_of_transport", "e_d", "work", "regime", "stick_fraction1",
    "stick_fraction2", "stick_fraction", "n_switch", "n_land", "u", "v1", "v2", "state", "stable", "residual", "n_iter",
    "liftoff", "slip_margin", "min_normal",
)  # fmt: skip
"""The gait's fields `gait` prints, besides `status` and the multipliers: under the paper's names
for the paper's model, else the bodies' (`stick_fraction`, `state`; `_PAPER_ONLY` left out)."""

_PAPER_ONLY = ("stick_fraction1", "stick_fraction2", "u", "v1", "v2")

POINT_FIELDS: tuple[str, ...] = (
    "lam", "mean_speed", "cost_of_transport", "regime", "stable", "liftoff", "u", "v1", "v2", "state",
    "stick_fraction", "slip_margin", "min_normal", "n_switch", "n_land",
)  # fmt: skip
"""The per-point [`Branch`][] fields `continue` reports: under the paper's names for the paper's model
(`u`, `v1`, `v2`, and `state`, a list per point: under `--contact hop` with the heights and vertical
velocities after them), else the bodies' (`state`, `stick_fraction`, a list per point)."""

_PAPER_POINT = ("u", "v1", "v2")


def _periods(text: str) -> tuple[int, ...]:
    try:
        ks = tuple(int(v) for v in text.split(",") if v.strip())
    except ValueError:
        ks = ()
    if not ks or any(k < 1 for k in ks):
        raise ValueError(f"--periods must be a comma-separated list of positive integers, got {text!r}.")
    return ks


def _pairs(z: Any) -> list:
    """Complex numbers as `[re, im]` pairs (NaN stays NaN, encoded as null)."""
    z = np.asarray(z)
    nan = np.isnan(z.real) | np.isnan(z.imag)
    return np.stack([z.real, np.where(nan, np.nan, z.imag)], axis=-1).tolist()


def gait_omega(omega: float) -> None:
    """Refuse a forcing without a period: `ValueError` naming `--omega` unless it is finite and > 0."""
    if not (math.isfinite(omega) and omega > 0):
        raise ValueError(f"--omega must be a finite number > 0 for a gait (its period is 2 pi / omega), got {omega!r}.")


def described(result: dict[str, Any], description: dict[str, Any], settings: dict[str, Any]) -> dict[str, Any]:
    """The JSON record of a result: its fields, the mechanism's `description` and the `settings`.
    A description key that names a field of the result too (a chain's spring stiffness `k` beside
    the gait period `k`) is kept as `mechanism_<key>`, so that neither hides the other."""
    ours = {(f"mechanism_{n}" if n in result else n): v for n, v in description.items()}
    return {**result, **ours, **settings}


def _fail(err: Exception) -> NoReturn:
    typer.echo(f"Error: {err}", err=True)
    raise typer.Exit(2) from None


def register(app: typer.Typer) -> None:
    """Add the `gait` and `continue` subcommands to `app`."""

    @app.command("gait")
    @friendly
    @expand(mech=mechanism_options(), run=run_options(("contact", "start", "dt")))
    def gait(
        file: Annotated[
            Path | None, typer.Argument(help="A mechanism file (TOML), instead of the mechanism options.")
        ] = None,
        *,
        mech: Values,
        run: Values,
        periods: Annotated[
            str, typer.Option(help="Gait periods to try, in actuation periods (e.g. 1,2,3,4).")
        ] = "1,2,3,4",
        transient: Annotated[int, typer.Option(help="Actuation periods integrated before Newton's method.")] = 30,
        as_json: Annotated[bool, typer.Option("--json", help="Print the gait as one JSON object.")] = False,
    ) -> None:
        """Solve the steady gait of one mechanism: speed, cost of transport, Floquet multipliers, status.

        The gait is a periodic orbit (fixed point of the period map), found by Newton's method
        after a short transient; stable means every Floquet multiplier lies inside the unit circle.
        The mechanism is the paper's model (its options), a chain (`--masses`) or a mechanism FILE.
        With --json, stdout is one JSON object: the gait's fields (per-body ones as lists), the
        mechanism and the settings; a complex multiplier is a pair [re, im].
        """
        import locomotion_jax as lj

        from ._files import echo_fields, note, plain

        ks = _periods(periods)
        if file is None and mech["omega"] is not None:  # before the wave's own check: a gait needs a period
            gait_omega(number("omega", mech["omega"]))
        built = build(mech, file)
        gait_omega(built.omega)
        note(f"solving the steady gait, periods {','.join(map(str, ks))} (compiling the solver: first call only)...")
        g = lj.steady_gait(built.mechanism, periods=ks, transient=transient, contact=run["contact"],
                           start=run["start"], dynamics=lj.Exact(dt=run["dt"]), **built.extra)  # fmt: skip
        skip = ("stick_fraction",) if g.names == PAPER else _PAPER_ONLY
        record: dict[str, Any] = {n: plain(getattr(g, n)) for n in GAIT_FIELDS if n not in skip}
        record["regime_name"] = lj.Regime(int(g.regime)).name
        record["status"] = int(g.status)
        record["status_name"] = lj.GaitStatus(int(g.status)).name
        record["multipliers"] = _pairs(g.multipliers)
        settings = {"periods": list(ks), "transient": transient, **run}
        if as_json:
            typer.echo(dumps(described(record, built.record, settings)))
            return
        typer.echo(built.head)
        typer.echo(f"status:     {record['status_name']}")
        echo_fields({n: v for n, v in record.items() if n not in ("status_name", "multipliers")})
        mult = ", ".join(_complex(z) for z in np.asarray(g.multipliers))
        typer.echo(f"  {'multipliers':<18} {mult}")

    @app.command("continue")
    @friendly
    @expand(mech=mechanism_options(), run=run_options(("contact", "start", "dt")))
    def continue_(
        file: Annotated[
            Path | None, typer.Argument(help="A mechanism file (TOML), instead of the mechanism options.")
        ] = None,
        *,
        parameter: Annotated[
            str,
            typer.Option(
                help="The parameter: the paper's model's omega, a, d, mhat, mu_s, mu_k, k, c, lbar (cosN, sinN of "
                "a Fourier waveform); a chain's or a mechanism's leaf (omega, mu_s, c: every entry, equal at the "
                "start) or one entry of it (m[1], mu_s_fwd[0]); a mechanism's element or friction law by its path "
                "(links[0].k, friction[0].mu_s_fwd)."
            ),
        ],
        stop: Annotated[float, typer.Option(help="Its end value (the start is the model option's value).")],
        mech: Values,
        run: Values,
        periods: Annotated[str, typer.Option(help="Gait periods to try at the start.")] = "1,2,3,4",
        max_points: Annotated[int, typer.Option(help="Points on the branch at most.")] = 200,
        max_step: Annotated[float, typer.Option(help="Largest step, in units of |stop - start|.")] = 0.04,
        out: Annotated[Path | None, typer.Option(help="Write the branch as JSON to this file.")] = None,
        as_json: Annotated[bool, typer.Option("--json", help="Print the branch as one JSON object.")] = False,
    ) -> None:
        """Follow the steady gait of one configuration along one parameter (pseudo-arclength continuation).

        Prints one line per point (parameter, speed, cost of transport, regime, stability) and the
        located events: folds, period doublings, the SSL/SL boundary and lift-off (to 1e-10 in the
        parameter). The mechanism is the paper's model (its options), a chain (`--masses`) or a
        mechanism FILE. With --json or --out, the points and events as one JSON object, with the
        mechanism (the paper's model's state under its names u, v1, v2; another's as a list).
        """
        import locomotion_jax as lj

        from ..gaits._bifurcation import NAMES

        built = build(mech, file)
        try:
            gait_omega(built.omega)
            b = lj.continuation(built.mechanism, parameter, stop, periods=_periods(periods), max_points=max_points,
                                max_step=max_step, step=min(0.01, max_step), contact=run["contact"],
                                start=run["start"], dynamics=lj.Exact(dt=run["dt"]), **built.extra)  # fmt: skip
        except ValueError as err:
            _fail(err)
        n, paper = int(b.n_points), b.names == PAPER
        skip = ("stick_fraction",) if paper else _PAPER_POINT
        points = {name: np.asarray(getattr(b, name))[:n].tolist() for name in POINT_FIELDS if name not in skip}
        points["multipliers"] = _pairs(np.asarray(b.multipliers)[:n])
        e = b.events
        kinds, state = np.asarray(e.kind), np.asarray(e.state)  # the orbit's section state per event

        def named(q: Any) -> dict[str, Any]:
            if paper:
                return dict(u=float(state[q, 0]), v1=float(state[q, 1]), v2=float(state[q, 2]))
            return dict(state=state[q].tolist())

        events = [
            dict(kind=NAMES[int(kinds[q])], lam=float(e.lam[q]), lam_error=float(e.lam_error[q]),
                 located=bool(e.located[q]), smooth=bool(e.smooth[q]), turn=bool(e.turn[q]), **named(q),
                 multipliers=_pairs(e.multipliers[q]))
            for q in np.flatnonzero(kinds >= 0)
        ]  # fmt: skip
        branch = dict(
            parameter=parameter, lam_start=float(b.lam[0]) if n else float("nan"), lam_stop=stop, k=int(b.k),
            status=int(b.status), status_name=_name(lj.BranchStatus, int(b.status)),
            start_status_name=_name(lj.GaitStatus, int(b.start_status)), n_points=n, points=points, events=events,
        )  # fmt: skip
        record = described(branch, built.record, run)
        if out is not None:
            try:
                out.parent.mkdir(parents=True, exist_ok=True)
                out.write_text(dumps(record, indent=1))
            except OSError as err:
                _fail(ValueError(f"--out {out}: cannot write ({err.strerror or err})."))
        if as_json:
            typer.echo(dumps(record))
            return
        typer.echo(f"{parameter} from {record['lam_start']:g} to {stop:g}: {n} points, k = {record['k']}, "
                   f"{record['status_name']} (start: {record['start_status_name']})")  # fmt: skip
        typer.echo(f"  {parameter:>12} {'speed':>12} {'cost':>10} {'regime':>6} {'stable':>6} {'|mu|max':>8}")
        mu = np.abs(np.asarray(b.multipliers)[:n])
        for j in range(n):
            reg = lj.Regime(int(points["regime"][j])).name
            typer.echo(f"  {points['lam'][j]:12.6g} {points['mean_speed'][j]:12.6g} "
                       f"{points['cost_of_transport'][j]:10.5g} {reg:>6} {str(points['stable'][j]):>6} "
                       f"{np.max(mu[j]):8.4f}")  # fmt: skip
        for ev in events:
            flags = ", ".join(f for f, on in (("non-smooth", not ev["smooth"]), ("turns", ev["turn"])) if on)
            typer.echo(f"event {ev['kind']:<16} {parameter} = {ev['lam']:.12g} (+- {ev['lam_error']:.1e})"
                       + (f" [{flags}]" if flags else ""))  # fmt: skip
        if out is not None:
            typer.echo(f"wrote {out}")


def _name(codes: type, value: int) -> str:
    for name, v in vars(codes).items():
        if name.isupper() and v == value:
            return name
    return str(value)


def _complex(z: complex) -> str:
    return f"{z.real:.6g}" if z.imag == 0 else f"{z.real:.6g}{z.imag:+.6g}j"
