"""Fig. 5: positions and velocities in SSL (omega = 0.2 wn1) and SL (omega = 2.3 wn1).

Zhou, Majidi, O'Reilly (2014); SPEC §6. Writes output/fig05.png, output/fig05.nc and
the reproduction report. Usage: python experiments/fig05.py [--quick] [--out DIR]
"""

import jax


jax.config.update("jax_enable_x64", True)  # start-up choice of the script, like the CLI's --x64

from locomotion_jax.paper._figures import script_main


if __name__ == "__main__":
    raise SystemExit(script_main("5"))
