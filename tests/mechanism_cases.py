"""The capsule robot of the mechanism tests (SPEC §9), built twice: by the package and for the
independent reference (`reference_mechanism`), which shares no code with it."""

from typing import Any

import locomotion_jax as lj
from docs_examples import doc_class
from reference_mechanism import Body, Sig, System


ANISO = (0.5, 0.2, 0.4, 0.15)
"""The shell's anisotropic Coulomb law: `(mu_s_fwd, mu_s_bwd, mu_k_fwd, mu_k_bwd)`."""


def capsule(a: Any = 0.6, k: Any = 10.0, w: float = 3.0, check: bool = True, law: tuple = ANISO) -> lj.Mechanism:
    """Body 0 on the ground (anisotropic Coulomb), body 1 carried by it on a spring k, driven by a sin(w t)."""
    links = [lj.Spring(0, 1, k=k, rest=0.0), lj.Force(0, 1, lj.Sinusoid(a=a, omega=w, lbar=0.0))]
    return lj.Mechanism(masses=[1.0, 0.5], friction=[lj.AnisotropicCoulomb(*law), None], carried_by=[None, 0],
                        links=links, check=check)  # fmt: skip


def capsule_ref(a: float, k: float, w: float, x0, v0, law: tuple = ANISO) -> System:
    """The same capsule for the reference, from positions `x0` and velocities `v0`."""
    bodies = [Body(1.0, law, x0=x0[0], v0=v0[0]), Body(0.5, None, carrier=0, x0=x0[1], v0=v0[1])]
    return System(bodies, springs=[(0, 1, k, 0.0)], forces=[(0, 1, Sig(0.0, (0.0,), (a,), w))])


class Cubed(doc_class("mechanisms.md", "Cubed")):
    """`docs/mechanisms.md`'s waveform class of a user's own, $\\ell_0 = \\bar\\ell + a \\sin^3 \\omega t$, which is
    the Fourier series $\\bar\\ell + \\tfrac{3a}{4}\\sin\\omega t - \\tfrac{a}{4}\\sin 3\\omega t$ (`fourier`,
    for the reference)."""

    def fourier(self) -> tuple[float, tuple, tuple]:
        """`(mean, A, B)` of the same signal for the reference's `Sig`."""
        a = float(self.a)
        return float(self.lbar), (0.0, 0.0, 0.0), (0.75 * a, 0.0, -0.25 * a)
