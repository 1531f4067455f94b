"""Your own physics in one short class, as the documentation writes it: each page's block runs as
a reader copies it, and the actuator it shows is the force it claims to be (the friction law and
the waveform are checked further in `test_chain.py`, `test_chain_array.py` and
`test_mechanism_array.py`, the dynamics class in `test_dynamics_extension.py`, all on the
classes read from the pages by `docs_examples`)."""

from typing import Any

import locomotion_jax as lj
import numpy as np
import pytest
from docs_examples import doc_class, run_block


@pytest.mark.parametrize(
    "page,name", [("mechanisms.md", "ViscousCoulomb"), ("mechanisms.md", "Cubed"), ("mechanisms.md", "Bellows"),
                  ("index.md", "HalfStep")],
)  # fmt: skip
def test_a_pages_class_runs_as_written(page, name):
    result, _ = run_block(page, name)
    assert isinstance(result, (lj.Trajectory, lj.Measurement))
    assert np.all(np.asarray(result.status) == lj.Status.OK)
    assert np.all(np.isfinite(np.asarray(result.e_d)))


@pytest.mark.parametrize("layout", ["unrolled", "array"])
def test_the_bellows_is_an_internal_force_of_area_times_pressure(layout):
    """`Bellows(area)` driven by pressures p equals `InternalForce()` driven by the forces area p, to
    rounding (area (a sin) against (area a) sin), in both layouts; the page's own run is the first."""
    Bellows = doc_class("mechanisms.md", "Bellows")
    bristles = lj.AnisotropicCoulomb(0.5, 0.9, 0.3, 0.7)
    wave = lambda a: lj.TravellingWave(a, 2.0, 1.0)
    chain = lambda a, actuator: lj.Chain(masses=[1.0] * 3, d=0.0, friction=bristles, waveforms=wave(a),
                                         actuator=actuator, layout=layout)  # fmt: skip
    bellows = lj.measure(chain(2.0, Bellows(area=0.4)), z=1.0)
    force = lj.measure(chain(0.8, lj.InternalForce()), z=1.0)
    assert int(bellows.status) == lj.Status.OK and bool(bellows.reached)
    for field in ("tau_z", "e_z", "mean_speed", "work", "e_d"):
        assert float(getattr(bellows, field)) == pytest.approx(float(getattr(force, field)), rel=1e-10), field
    assert float(bellows.tau_z) == pytest.approx(81.96, abs=0.005)  # as the page says
    assert abs(float(bellows.balance)) < 1e-6 * float(bellows.e_d)


def test_an_actuator_is_one_for_the_whole_batch():
    """An actuator's field of several values is refused, named; a number of any type is taken."""
    Bellows = doc_class("mechanisms.md", "Bellows")
    with pytest.raises(ValueError, match=r"'actuator'.*Bellows\.area of shape \(2,\)"):
        lj.Chain(masses=[1.0] * 3, actuator=Bellows(area=np.array([0.4, 0.5])))
    for area in (0.4, np.float64(0.4)):
        actuator: Any = lj.Chain(masses=[1.0] * 3, actuator=Bellows(area=area)).actuator
        assert actuator.area == 0.4
