"""One `Trajectory` and one `Measurement` for every mechanism: per-body fields with a trailing body
axis, the paper's names (`x1`, `N2`, `mode`, `l0`, `stick_fraction1`, ...) for two bodies, and
`to_numpy` keys that a run of the paper's model has always had (the sweeps' datasets, the `.npz`
files and `benchmarks/compare_results.py` read them)."""

import warnings

import jax.numpy as jnp
import locomotion_jax as lj
import numpy as np
import pytest
from locomotion_jax._status import mode_code


PARAMS = lj.Params(omega=jnp.array([2.0, 9.0]))
CHAIN = lj.Chain(masses=[1.0, 1.0, 1.0], waveforms=lj.TravellingWave(a=0.06, omega=2.0, phi=1.0))
SAVE = np.linspace(0.0, 4.0, 9)

PAPER_TRAJECTORY_KEYS = [
    "t", "x1", "v1", "x2", "v2", "X", "e_d", "w", "e", "mode", "l0", "N1", "N2", "f_ex", "valid", "status",
    "liftoff", "t_liftoff", "n_switch", "transversality", "near_miss", "switch_gap",
]  # fmt: skip
PAPER_MEASUREMENT_KEYS = [
    "tau_z", "e_z", "reached", "regime", "mean_speed", "cost_of_transport", "stick_fraction1", "stick_fraction2",
    "e_d", "work", "delta_e", "balance", "liftoff", "t_liftoff", "status", "t_start", "X_start", "n_steps",
    "n_switch", "transversality", "near_miss", "margin_z",
]  # fmt: skip


def test_paper_trajectory_names_and_keys():
    tr = lj.simulate(PARAMS, 4.0, SAVE)
    assert isinstance(tr, lj.Trajectory) and tr.n_bodies == 2
    assert tr.x.shape == (2, 9, 2) and tr.N.shape == (2, 9, 2) and tr.rest_length.shape == (2, 9, 1)
    assert tr.tension is None and tr.f_ex is not None
    out = tr.to_numpy()
    assert list(out) == PAPER_TRAJECTORY_KEYS
    for name, i in (("x", 0), ("x", 1), ("v", 0), ("v", 1), ("N", 0), ("N", 1)):
        np.testing.assert_array_equal(out[f"{name}{i + 1}"], np.asarray(getattr(tr, name))[..., i])
    assert out["l0"].shape == (2, 9) and out["mode"].dtype == np.int32
    np.testing.assert_array_equal(out["mode"], np.asarray(mode_code(tr.stuck[..., 0], tr.stuck[..., 1])))
    # The mode of Sect. 2.2 from the stuck flags: stuck means v = 0 exactly, and mode 1 means both slip.
    v, mode = np.asarray(tr.v), out["mode"]
    assert np.all(v[..., 0][np.isin(mode, [0, 3])] == 0.0) and np.all(v[..., 1][np.isin(mode, [0, 2])] == 0.0)
    assert (mode == lj.Mode.BOTH_STICK).any() or (mode != lj.Mode.BOTH_SLIP).any()


def test_paper_measurement_names_and_keys():
    m = lj.measure(PARAMS, z=0.5, horizon=40.0, t_start=4.0)
    assert isinstance(m, lj.Measurement) and m.stick_fraction.shape == (2, 2)
    out = m.to_numpy()
    assert list(out) == PAPER_MEASUREMENT_KEYS
    np.testing.assert_array_equal(out["stick_fraction1"], np.asarray(m.stick_fraction)[:, 0])
    np.testing.assert_array_equal(np.asarray(m.stick_fraction2), np.asarray(m.stick_fraction)[:, 1])


def test_chain_result_is_the_same_class_and_refuses_the_paper_names():
    tr = lj.simulate(CHAIN, 4.0, SAVE)
    assert type(tr) is lj.Trajectory and tr.n_bodies == 3 and tr.f_ex is None
    assert tr.tension is not None and tr.tension.shape == (9, 2) and tr.rest_length.shape == (9, 2)
    out = tr.to_numpy()
    assert "x1" not in out and out["x"].shape == (9, 3) and out["l0"].shape == (9, 2) and "rest_length" not in out
    for name in ("x1", "v2", "N1", "l0", "mode"):
        with pytest.raises(ValueError, match=rf"`{name}` is the paper's name .* this result has 3 bodies"):
            getattr(tr, name)
    m = lj.measure(CHAIN, z=0.2, horizon=40.0, t_start=4.0)
    assert type(m) is lj.Measurement and m.stick_fraction.shape == (3,) and "stick_fraction" in m.to_numpy()
    with pytest.raises(ValueError, match="`stick_fraction1` is the paper's name .* 3 bodies"):
        _ = m.stick_fraction1


def test_two_body_chain_has_the_paper_names():
    tr = lj.simulate(lj.Chain.from_params(lj.Params(omega=2.0)), 4.0, SAVE)
    np.testing.assert_array_equal(np.asarray(tr.x2), np.asarray(tr.x)[:, 1])
    np.testing.assert_array_equal(np.asarray(tr.l0), np.asarray(tr.rest_length)[:, 0])
    assert "x" in tr.to_numpy() and "x1" not in tr.to_numpy()  # named as the fields: not the paper's model


def test_chain_names_are_deprecated_aliases():
    for old, new in (("ChainTrajectory", lj.Trajectory), ("ChainMeasurement", lj.Measurement)):
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            assert getattr(lj, old) is new
        assert any(issubclass(w.category, DeprecationWarning) and old in str(w.message) for w in caught)


def _optimum_fields(cls, **given):
    """Every field of an optimum class: `given`, else a number, a flag, a list or an array by its type."""
    import dataclasses

    by_type = {"float": 0.25, "int": 2, "bool": True, "str": "fourier", "list": [], "dict": {}}
    out = {}
    for f in dataclasses.fields(cls):
        if f.name in given:
            out[f.name] = given[f.name]
            continue
        t = str(f.type)
        typed = (v for k, v in by_type.items() if t.startswith(k) or t == f"<class '{k}'>")
        out[f.name] = np.array([[0.5, -0.25]]) if "ndarray" in t else next(typed, None)
    return out


def test_every_optimum_has_the_shared_interface():
    """The three optimisers' results (`Optimum`, `ChainOptimum`, `MechanismOptimum`) share one interface
    (`optimisation._optimum.AbstractOptimum`): `to_dict` leaves out the mechanism object and, unless
    `full`, the candidates; `to_json` is that dict; `summary` reports the requirement, the cost and
    the feasibility."""
    import json

    from locomotion_jax.optimisation._optimum import AbstractOptimum

    links = [lj.Spring(0, 1, k=10.0, rest=0.0), lj.Force(0, 1, lj.Sinusoid(0.6, 3.0, 0.0))]
    mech = lj.Mechanism(masses=[1.0, 0.5], friction=[lj.Coulomb(0.5, 0.4), None], carried_by=[None, 0], links=links)
    cases = [
        (
            lj.Optimum,
            dict(
                constraints_exact={"speed": True},
                sinusoid=None,
                lbar=1.0,
                method="exact",
                control=None,
                cos=np.array([0.5, 0.0]),
                sin=np.array([0.0, -0.25]),
            ),
        ),  # fmt: skip
        (
            lj.ChainOptimum,
            dict(
                chain=CHAIN,
                constraints_exact={"speed": True},
                travelling_wave=None,
                stroke_exact=np.array([0.05, 0.05]),
            ),
        ),  # fmt: skip
        (
            lj.MechanismOptimum,
            dict(mechanism=mech, elements=[2], sinusoid=None, control=None, harmonics=2, stroke_exact=np.array([0.5])),
        ),  # fmt: skip
    ]
    for cls, given in cases:
        opt = cls(**_optimum_fields(cls, candidates=[{"cost": 1.0}], cost_of_transport_exact=1.2345, **given))
        assert isinstance(opt, AbstractOptimum)
        brief, full = opt.to_dict(), opt.to_dict(full=True)
        assert "candidates" not in brief and full["candidates"] == [{"cost": 1.0}]
        assert not {"chain", "mechanism"} & set(full), cls
        assert json.loads(opt.to_json()) == brief
        text = opt.summary()
        assert "1.234" in text and "FEASIBLE" in text and "0.25" in text, text
