"""Inputs of the hopping reading (issue 27, SPEC §10): `contact="hop"` is a `Contact`, and
`Mechanism` takes `y0`, `w0`, `restitution` and `zeno_speed`, validated with errors that name
the field and the body. A front end that does not run the hopping reading yet refuses
`contact="hop"` with a clear error instead of running another reading."""

import typing
from typing import Any

import jax.numpy as jnp
import locomotion_jax as lj
import numpy as np
import pytest
from locomotion_jax._custom_types import Contact


def ball(**kw: Any) -> lj.Mechanism:
    args: dict[str, Any] = dict(
        masses=[1.0], friction=lj.Coulomb(0.5, 0.5), c=0.0, x0=[0.0], v0=[0.0], y0=[1.0], restitution=0.5
    )
    args.update(kw)
    return lj.Mechanism(**args)


def test_contact_type_has_hop():
    assert typing.get_args(Contact) == ("strict", "paper", "hop")


def test_mechanism_vertical_fields():
    b = ball(w0=[-0.25])
    assert np.asarray(b.y0).tolist() == [1.0]
    assert np.asarray(b.w0).tolist() == [-0.25]
    assert np.asarray(b.restitution).tolist() == [0.5]
    assert float(b.zeno_speed) == 1e-3
    d = lj.Mechanism(masses=[1.0, 2.0])
    assert np.asarray(d.y0).tolist() == [0.0, 0.0]
    assert np.asarray(d.restitution).tolist() == [0.0, 0.0]  # plastic by default


def test_mechanism_vertical_fields_batch():
    b = ball(restitution=jnp.array([[0.0], [0.5], [1.0]]))
    assert b.batch_shape == (3,)
    assert b[1].restitution.tolist() == [0.5]
    assert b[1].y0.tolist() == [1.0]
    assert bool(b.is_valid().all())


@pytest.mark.parametrize(
    "kw, words",
    [
        (dict(restitution=[1.5]), ["restitution", "body 0", "0 <= e_i <= 1"]),
        (dict(restitution=[-0.1]), ["restitution", "body 0", "0 <= e_i <= 1"]),
        (dict(y0=[-0.5]), ["y0", "body 0", "y0_i >= 0"]),
        (dict(y0=[np.nan]), ["y0", "body 0", "finite"]),
        (dict(w0=[np.inf]), ["w0", "body 0", "finite"]),
        (dict(zeno_speed=-1.0), ["zeno_speed", "zeno_speed >= 0"]),
    ],
)
def test_mechanism_vertical_fields_refused(kw, words):
    with pytest.raises(ValueError) as err:
        ball(**kw)
    for w in words:
        assert w in str(err.value)


def test_second_body_named():
    with pytest.raises(ValueError, match="body 1"):
        lj.Mechanism(masses=[1.0, 1.0], y0=[0.0, -1.0])


def test_carried_body_has_no_vertical_motion():
    with pytest.raises(ValueError, match="body 1.*no vertical motion"):
        lj.Mechanism(masses=[1.0, 0.5], friction=[lj.Coulomb(0.5, 0.4), None], carried_by=[None, 0], y0=[0.0, 0.3])


def test_invalid_flagged_in_batch_without_check():
    b = ball(restitution=jnp.array([[0.5], [2.0], [0.0]]), check=False)
    assert np.asarray(b.is_valid()).tolist() == [True, False, True]


def test_wrong_length_refused():
    with pytest.raises(ValueError, match="restitution"):
        ball(restitution=[0.5, 0.5])


def test_hop_front_ends_refuse_clearly():
    """Paths that do not run the hopping reading yet say so, and a hopping gait's start without heights is
    refused naming them (`simulate` and `measure` of a Mechanism,
    a Chain and Params run it: tests/test_hop.py, tests/test_hop_reference.py, tests/test_hop_params.py)."""
    ts = np.linspace(0.0, 1.0, 5)
    with pytest.raises(NotImplementedError, match="contact='hop'.*Exact"):
        lj.measure(ball(), contact="hop", dynamics=lj.Smoothed())
    with pytest.raises(NotImplementedError, match="contact='hop'.*Exact"):
        lj.simulate(lj.Params(), t_end=1.0, save_at=ts, contact="hop", dynamics=lj.Smoothed())
    with pytest.raises(ValueError, match=r"vertical velocities w_0..w_N-1\) of shape \(7,\), got shape \(3,\)"):
        lj.steady_gait(lj.Params(omega=2.0), contact="hop", start=np.asarray([3.0, 0.0, 0.0]))  # (u, v1, v2) only
    with pytest.raises(ValueError, match="'strict', 'paper' or 'hop'"):
        lj.simulate(lj.Params(), t_end=1.0, save_at=ts, contact="bounce")  # type: ignore[arg-type]


def test_zeno_sequence_flagged_in_a_batch_others_unaffected():
    """A batch of bodies: one dropped with e = 0.5 bounces ever faster (a Zeno sequence: infinitely
    many landings before t = 3 sqrt 2) and is stopped by the Zeno rule at its 11th landing and
    flagged; the others (plastic, thrown sideways, and never landing) are not flagged, and each is
    bitwise the run of its own configuration alone."""
    ts = np.linspace(0.0, 6.0, 121)
    y0 = jnp.array([[1.0], [0.5], [0.0], [3.0]])
    e = jnp.array([[0.5], [0.0], [0.5], [0.5]])
    v0 = jnp.array([[0.0], [1.0], [0.3], [0.0]])
    w0 = jnp.array([[0.0], [0.0], [0.0], [4.0]])
    batch = ball(y0=y0, restitution=e, v0=v0, w0=w0)
    tr = lj.simulate(batch, t_end=6.0, save_at=ts, contact="hop")
    assert tr.zeno is not None and tr.n_land is not None
    print("zeno flags", np.asarray(tr.zeno), "landings", np.asarray(tr.n_land), "status", np.asarray(tr.status))
    assert np.asarray(tr.zeno).tolist() == [True, False, False, False]
    assert np.asarray(tr.n_land).tolist()[:2] == [11, 1] and np.all(np.asarray(tr.status) == lj.Status.OK)
    assert tr.y is not None and np.all(np.asarray(tr.y[0, ts > 4.25]) == 0)  # at rest on the ground after the Zeno rule
    for i in range(1, 4):
        one = lj.simulate(ball(y0=y0[i], restitution=e[i], v0=v0[i], w0=w0[i]), t_end=6.0, save_at=ts, contact="hop")
        for k in ("x", "v", "y", "vy", "e_d", "e", "n_land", "zeno", "status"):
            assert np.array_equal(np.asarray(getattr(tr, k)[i]), np.asarray(getattr(one, k))), (i, k)
    m = lj.measure(batch, z=1e3, horizon=6.0, window=6.0, t_start=0.0, contact="hop")
    assert m.zeno is not None and np.asarray(m.zeno).tolist() == [True, False, False, False]
