"""Fig. 4b: centre-of-mass displacement X(t) for d in {-0.5, -0.25, 0, 0.25, 0.5}.

Zhou, Majidi, O'Reilly (2014); SPEC §6. Writes output/fig04b.png, output/fig04b.nc and
the reproduction report. Usage: python experiments/fig04b.py [--quick] [--out DIR]
"""

import jax


jax.config.update("jax_enable_x64", True)  # start-up choice of the script, like the CLI's --x64

from locomotion_jax.paper._figures import script_main


if __name__ == "__main__":
    raise SystemExit(script_main("4b"))
