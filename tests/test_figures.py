"""The paper's qualitative claims (SPEC §6) on small grids, and the figure pipeline.

Small means seconds: dt = 0.02, short horizons, a handful of configurations
chosen where the claims are decided (0.2 wn1 is SSL, 2.3 wn1 is SL, ...).
"""

import locomotion_jax as lj
import numpy as np
import pytest
import xarray as xr
from locomotion_jax._status import Regime
from locomotion_jax.paper import _fig_sweep as fsw, _fig_time as ftime
from locomotion_jax.paper._figtools import local_minima, runs, steady_liftoff
from locomotion_jax.paper._figures import FIGURES, resolve, run_figures


def test_fig5_and_fig10_ssl_sticks_sl_slides():
    ds = ftime.data_5(ftime.SIZES_5["quick"])
    v5 = ftime.check_5(ds)
    assert v5.facts == dict(ssl_sticks=True, sl_never_sticks=True), v5.summary
    assert list(ds.regime.values) == [Regime.SSL, Regime.SL]
    v10 = ftime.check_10(ds)
    assert v10.facts["half_period"], v10.summary  # F_ex has half the actuation period
    assert v10.facts["similar_speed"], v10.summary


def test_fig8_fastest_and_costliest_near_wn1_ssl_at_low_frequency():
    ratios = np.array([0.1, 0.2, 0.6, 0.8, 0.85, 0.9, 1.0, 1.2, 2.0])
    ds = fsw.data_8(dict(ratios=ratios, dt=0.02, horizon=400.0, chunk=ratios.size))
    v = fsw.check_8(ds)
    assert v.facts["fastest_near_wn1"] and v.facts["most_energy_near_wn1"], v.summary
    ssl = ds.regime.values == Regime.SSL
    assert ssl[ratios < 0.3].all() and not ssl[ratios > 0.5].any()
    # SSL is the energy-efficient regime: less dissipation per distance than any SL point.
    assert np.nanmax(ds.e_z.values[ssl]) < np.nanmin(ds.e_z.values[~ssl])
    # The resonance band is where the paper's n = |N| reading hides lift-off (SPEC §1).
    assert ds.liftoff.values[(ratios >= 0.85) & (ratios <= 1.2)].all()


def test_fig12_mass_ratio_minima():
    mh = np.array([0.05, 0.15, 0.27, 0.38, 0.5, 0.62, 0.73, 0.85, 0.95])
    ds = fsw.data_12(dict(mhat=mh, omegas=(2.0, 6.0, 23.0), dt=0.02, horizon=400.0, chunk=mh.size))
    tau = {om: ds.tau_z.sel(omega=om).values for om in (2.0, 6.0, 23.0)}
    i = {m: int(np.argmin(np.abs(mh - m))) for m in mh}
    # omega = 23: minima near 0.05, 0.5 and 0.95 (wn1 = 23 at mhat ~ 0.05 and 0.95).
    assert tau[23.0][i[0.05]] < tau[23.0][i[0.15]] and tau[23.0][i[0.95]] < tau[23.0][i[0.85]]
    assert tau[23.0][i[0.5]] < min(tau[23.0][i[0.38]], tau[23.0][i[0.62]])
    # omega = 6: minima near 0.27, 0.5 and 0.73 (wn2 or wn3 close to 6).
    assert tau[6.0][i[0.27]] < tau[6.0][i[0.38]] and tau[6.0][i[0.73]] < tau[6.0][i[0.62]]
    assert tau[6.0][i[0.5]] < min(tau[6.0][i[0.38]], tau[6.0][i[0.62]])
    # omega = 2: motion only near mhat = 0.5.
    reached = ds.reached.sel(omega=2.0).values
    assert reached[i[0.5]] and not reached[np.abs(mh - 0.5) > 0.2].any()


def test_steady_liftoff_in_padded_calls_equals_each_configurations_simulation():
    # The re-simulations run in calls of `chunk` rows, NaN past the configurations: chunks of 4
    # (a partial second one) give what one call gives, and each configuration's lowest normal
    # force is that of its own `simulate` over the same window.
    axes = {"omega": [6.0, 9.5, 16.0], "a": [0.05, 0.1]}
    ds = xr.Dataset(coords=axes)
    ds["liftoff"] = (("omega", "a"), np.asarray([[False, True], [True, True], [True, True]]))
    one = steady_liftoff(ds.copy(), dt=0.02, window=2.0, n_save=41)
    four = steady_liftoff(ds.copy(), dt=0.02, window=2.0, n_save=41, chunk=4)
    np.testing.assert_array_equal(one.min_normal, four.min_normal)
    np.testing.assert_array_equal(one.liftoff_steady, four.liftoff_steady)
    assert np.isnan(one.min_normal[0, 0]) and not one.liftoff_steady[0, 0]  # not flagged: not re-simulated
    p = lj.Params(omega=16.0, a=0.1)
    t = float(p.t_start) + np.linspace(0.0, 2.0, 41)
    tr = lj.simulate(p, float(t[-1]), t, dynamics=lj.Exact(0.02), contact="paper", start="paper")
    assert float(one.min_normal[2, 1]) == float(np.minimum(tr.N1, tr.N2).min())
    assert bool(one.liftoff_steady[2, 1]) == (float(one.min_normal[2, 1]) <= 0)


def test_run_figures_fig4b_direction_follows_d(tmp_path):
    paths = run_figures(["4b"], quick=True, out=tmp_path)
    png = tmp_path / "fig04b.png"
    assert png in paths and png.stat().st_size > 10_000
    report = (tmp_path / "REPRODUCTION.md").read_text()
    assert "## Fig. 4b" in report and "![Fig. 4b](fig04b.png)" in report and "YES" in report
    # The claim itself, from the data file the figure wrote.
    ds = xr.load_dataset(tmp_path / "fig04b.nc", engine="h5netcdf")
    v = ftime.check_4b(ds)
    assert v.facts == dict(forward=True, backward=True, stationary=True), v.summary
    dx = ds.X.values[:, -1] - ds.X.values[:, 0]
    # The motion grows with |d| (d = +-0.5 moves further than d = +-0.25).
    assert abs(dx[0]) > abs(dx[1]) > 0 and abs(dx[4]) > abs(dx[3]) > 0


def test_bad_arguments_fail_before_computing(tmp_path):
    with pytest.raises(ValueError, match="Unknown figure"):
        run_figures(["11"], quick=True, out=tmp_path)
    blocker = tmp_path / "file"
    blocker.write_text("")
    with pytest.raises(ValueError, match="cannot be written"):
        run_figures(["4b"], quick=True, out=blocker / "sub")
    assert resolve(["fig08", "04b", "8"]) == ["8", "4b"]
    assert resolve([]) == list(FIGURES)


def test_helpers():
    y = np.array([5.0, 3.0, 4.0, np.inf, 2.0, 2.05, 1.0, 6.0])
    assert list(local_minima(y)) == [1, 4, 6]
    assert list(local_minima(y, depth=0.1)) == [1, 6]
    assert runs(np.array([0, 1, 1, 0, 1], bool)) == [(1, 2), (4, 4)]
