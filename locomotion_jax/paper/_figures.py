"""Every figure of the paper from one call: `run_figures(figs, quick, out)`.

Each figure (SPEC §6) is a `FigureSpec`: a data function (an `xarray.Dataset`,
written as `out/figNN.nc`), a plot function (`out/figNN.png`) and a check of the
paper's claim on that data, which the report (`out/REPRODUCTION.md`) quotes.
The `experiments/figNN.py` scripts and the CLI's `figures` command call this.

Two sizes: `quick` (CI: all figures in a few minutes) and `default` (the
README's main job on a 2-core CPU; Fig. 6 and Fig. 8 far denser than the paper).
"""

import argparse
import dataclasses
import os
import sys
import tempfile
import time
from collections.abc import Callable, Iterable
from pathlib import Path

import jax
import numpy as np
import xarray as xr

from . import _fig_map as fmap, _fig_sweep as fsw, _fig_time as ftime
from ._figtools import Verdict
from ._report import write_report


DEFAULT_OUT = Path("experiments/output")
"""Default output directory of the `experiments/figNN.py` scripts, relative to the working
directory as the CLI's `figures --out` default: from the repository root, the committed
reference figures and report. Every run writes only into its output directory."""

COMMON_READINGS = (
    "Contact reading $n_i = |N_i|$ (paper) and start eq. (14), as SPEC §1 prescribes for reproductions.",
)


@dataclasses.dataclass(frozen=True)
class FigureSpec:
    """One figure of the paper: what it claims, how to compute, draw and check it."""

    name: str
    title: str
    claim: str
    readings: tuple[str, ...]
    notes: tuple[str, ...]
    sizes: dict[str, dict]
    data: Callable[[dict], xr.Dataset]
    plot: Callable[[xr.Dataset, Path], None]
    check: Callable[[xr.Dataset], Verdict]

    @property
    def stem(self) -> str:
        digits = "".join(ch for ch in self.name if ch.isdigit())
        return "fig" + digits.zfill(2) + self.name[len(digits) :]


_PERIODS = "The time axis shows the first 3 actuation periods after $t_s$ of the 25-unit window that the check uses."
FIGURES: dict[str, FigureSpec] = {
    s.name: s
    for s in (
        FigureSpec(
            "4b",
            "centre-of-mass displacement X(t) for five offsets d",
            "moves forward for d>0, backward for d<0, stationary for d=0",
            (
                "$\\omega = \\pi$ in the dimensionless model ($\\ell_0 = 0.05\\sin(\\pi t) + 3$) and $c = 0.01$ "
                "(SPEC §6); the caption gives no damping.",
                "Plotted from $t = 0$ (no transient removed), as the paper's figure starts at rest; "
                "$x(t) - x(0)$ on the vertical axis.",
            ),
            (),
            ftime.SIZES_4B,
            ftime.data_4b,
            ftime.plot_4b,
            ftime.check_4b,
        ),
        FigureSpec(
            "5",
            "positions and velocities in SSL (0.2 wn1) and SL (2.3 wn1)",
            "SSL shows sticking intervals, SL none",
            (
                "Positions are shown relative to their values at $t_s$ (both drift forward).",
                _PERIODS,
                "Stuck fractions are taken over the paper's window [t_s, t_s + 25].",
            ),
            (),
            ftime.SIZES_5,
            ftime.data_5,
            ftime.plot_5,
            ftime.check_5,
        ),
        FigureSpec(
            "6",
            "SSL region in the (a, omega) plane",
            "SSL only below the natural frequencies and at small a; omega matters most; the boundary has sharp peaks",
            (
                f"Ranges a in [{fmap.A_RANGE[0]:g}, {fmap.A_RANGE[1]:g}], omega in [{fmap.OMEGA_RANGE[0]:g}, "
                f"{fmap.OMEGA_RANGE[1]:g}] (the paper's are not stated).",
                "Each configuration runs only to the end of the regime window (horizon = window = 25).",
                "Runs in which both masses stay stuck through the window are drawn as 'at rest': the paper's rule "
                "counts them as SSL (a mass sticks), but nothing moves.",
                "dt = 0.02 for the map (only the regime is needed; switching times are located exactly); a random "
                "sample is re-run at dt = 0.01 to measure the agreement (default size).",
            ),
            (
                "The paper notes that its boundary peaks were 'very sensitive to tolerances in our numerical "
                "integration'; ours come from exact event location on a much denser grid, so individual peaks "
                "need not coincide.",
            ),
            fmap.SIZES_6,
            fmap.data_6,
            fmap.plot_6,
            fmap.check_6,
        ),
        FigureSpec(
            "7",
            "tau_5 vs mu_s - mu_k at omega = 0.2 wn1",
            "larger static friction helps in a range; effect small overall",
            ("mu_s from 0.5 to 1.0 at mu_k = 0.5, as the caption states.",),
            (),
            fsw.SIZES_7,
            fsw.data_7,
            fsw.plot_7,
            fsw.check_7,
        ),
        FigureSpec(
            "8",
            "tau_5 and e_5 vs omega/wn1",
            "fastest near wn1 (with the most energy); local minima near wn2 = wn3; several sensitive minima in "
            "the SSL range omega/wn1 < 0.3",
            ("omega/wn1 from 0.05 to 2.5 (the paper's range is not stated); logarithmic vertical axes.",),
            (
                "SPEC §1: a band of frequencies around resonance loses contact, so the paper's minimum of tau_5 "
                "near wn1 lies where the model's own assumption fails. With the pre-stretched start (eq. 14) the "
                "band of any lift-off is wider than the band where the steady motion itself loses contact (both "
                "are listed above and drawn: hatched vs dotted).",
            ),
            fsw.SIZES_8,
            fsw.data_8,
            fsw.plot_8,
            fsw.check_8,
        ),
        FigureSpec(
            "9",
            "tau_5 and e_5 vs a for five omegas",
            "faster costs more energy; for a > 0.08, omega = 0.6 wn1 beats 1.6 wn1 in time and energy",
            (
                "a from 0.01 to 0.15 (the paper discusses a <= 0.08 and a > 0.08 but does not state its range).",
                "'faster costs more' is tested as a positive rank correlation between speed 5/tau_5 and e_5.",
            ),
            (
                "SPEC §1: with the pre-stretched start (eq. 14), large a at high omega lifts a mass off in the "
                "first period (e.g. a >= 0.08 at omega = 23).",
            ),
            fsw.SIZES_9,
            fsw.data_9,
            fsw.plot_9,
            fsw.check_9,
        ),
        FigureSpec(
            "10",
            "friction + damping force F_ex (eq. 17) and velocities, SSL vs SL",
            "force period is half the actuation period; SL force amplitude about twice SSL's at similar speed",
            (
                "$F_{ex}\\cdot E_1 = m_1\\ddot x_1 + m_2\\ddot x_2$: the total friction (static or kinetic) plus "
                "damping force; amplitude = half the peak-to-peak value over the window.",
                "The period is read from the spectrum of $F_{ex}$ over a whole number of actuation periods: "
                "the period is T/g, g the greatest common divisor of the harmonics of omega that carry more than "
                "1% of the power ('half the period' = g = 2).",
                _PERIODS,
            ),
            (),
            ftime.SIZES_5,
            ftime.data_10,
            ftime.plot_10,
            ftime.check_10,
        ),
        FigureSpec(
            "12",
            "natural frequencies, tau_5 and e_5 vs the mass ratio",
            "at 23: minima of tau_5 near mhat 0.05, 0.5, 0.95; at 6: near 0.27, 0.5, 0.73; at 2: motion only near 0.5",
            (
                "$m_1 + m_2 = 2$ at every mass ratio (SPEC §6), so $m_1 = 2\\hat m$; mhat from 0.02 to 0.98.",
                "$t_s$ = 80 periods of the lowest natural frequency at each mass ratio.",
                "A minimum 'near' a value: a local minimum of tau_5 within max(0.05, 1.5 grid steps).",
            ),
            (),
            fsw.SIZES_12,
            fsw.data_12,
            fsw.plot_12,
            fsw.check_12,
        ),
    )
}


def resolve(figs: Iterable[str]) -> list[str]:
    """Canonical figure names ("4b", "8", ...) from user input ("fig08", "04b", "8"); all if empty."""
    names = []
    for raw in figs:
        key = str(raw).strip().lower().removeprefix("fig").removeprefix(".").strip().lstrip("0")
        if key not in FIGURES:
            raise ValueError(f"Unknown figure {raw!r}; valid figures are {', '.join(FIGURES)}.")
        if key not in names:
            names.append(key)
    return names or list(FIGURES)


def _check_writable(out: Path) -> None:
    try:
        out.mkdir(parents=True, exist_ok=True)
        with tempfile.NamedTemporaryFile(dir=out):
            pass
    except OSError as err:
        raise ValueError(f"Output directory {str(out)!r} cannot be written: {err}") from None


def _version() -> str:
    from .. import __version__

    return __version__


def _write_nc(ds: xr.Dataset, path: Path) -> None:
    ds = ds.copy()
    ds.attrs = {k: (int(v) if isinstance(v, (bool, np.bool_)) else v) for k, v in ds.attrs.items() if v is not None}
    tmp = path.with_suffix(".nc.tmp")
    ds.to_netcdf(tmp, engine="h5netcdf")
    os.replace(tmp, path)


def run_figures(figs: list[str], quick: bool, out: Path) -> list[Path]:
    """Compute, plot and check the requested figures; write the report.

    **Arguments:**

    - `figs`: figure names ("4b", "5", "6", "7", "8", "9", "10", "12"; "fig08" etc. also
      accepted); empty for all.
    - `quick`: the small CI size instead of the default size.
    - `out`: output directory; receives `figNN.png`, `figNN.nc` and `REPRODUCTION.md`,
      and nothing is written outside it.

    **Returns:** the paths written (PNGs, data files, reports).

    **Raises:** `ValueError` for an unknown figure or an unwritable `out`, before any computation.
    """
    names = resolve(figs)
    out = Path(out)
    _check_writable(out)
    if not jax.config.read("jax_enable_x64"):
        print("note: JAX runs in float32; the figures are meant for float64 (--x64).", file=sys.stderr)
    size_name = "quick" if quick else "default"
    written: list[Path] = []
    for name in names:
        spec = FIGURES[name]
        size = dict(spec.sizes[size_name], progress=not quick)
        print(f"Fig. {name} ({size_name}) ...", file=sys.stderr, flush=True)
        t0, c0 = time.perf_counter(), time.process_time()
        ds = spec.data(size)
        elapsed, cpu = time.perf_counter() - t0, time.process_time() - c0
        dtype = next((str(v.dtype) for v in ds.data_vars.values() if v.dtype.kind == "f"), "?")
        ds.attrs.update(
            figure=name, size=size_name, run_time_s=elapsed, cpu_time_s=cpu, dtype=dtype, package_version=_version()
        )
        nc, png = out / f"{spec.stem}.nc", out / f"{spec.stem}.png"
        _write_nc(ds, nc)
        spec.plot(ds, png)
        verdict = spec.check(ds)
        print(f"Fig. {name}: {elapsed:.1f} s; claim holds: {verdict.summary}", file=sys.stderr, flush=True)
        written += [png, nc]
    return written + write_reports(out)


def write_reports(out: Path) -> list[Path]:
    """(Re)build `out/REPRODUCTION.md` from the data files in `out`, without recomputing.

    **Returns:** `[out / "REPRODUCTION.md"]`, the one file written.
    """
    out = Path(out)
    return [write_report(list(FIGURES.values()), out, out / "REPRODUCTION.md", _version())]


def script_main(fig: str, argv: list[str] | None = None) -> int:
    """Entry point of `experiments/figNN.py`: `[--quick] [--out DIR]`."""
    parser = argparse.ArgumentParser(description=f"Reproduce Fig. {fig} of Zhou, Majidi, O'Reilly (2014).")
    parser.add_argument("--quick", action="store_true", help="small CI size")
    parser.add_argument("--out", type=Path, default=DEFAULT_OUT, help=f"output directory (default {DEFAULT_OUT})")
    args = parser.parse_args(argv)
    try:
        paths = run_figures([fig], args.quick, args.out)
    except ValueError as err:
        print(f"error: {err}", file=sys.stderr)
        return 2
    for p in paths:
        print(p)
    return 0
