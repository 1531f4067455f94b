"""Fig. 6: the SSL region in the (a, omega) plane.

Zhou, Majidi, O'Reilly (2014); SPEC §6. Writes output/fig06.png, output/fig06.nc and
the reproduction report. Usage: python experiments/fig06.py [--quick] [--out DIR]
"""

import jax


jax.config.update("jax_enable_x64", True)  # start-up choice of the script, like the CLI's --x64

from locomotion_jax.paper._figures import script_main


if __name__ == "__main__":
    raise SystemExit(script_main("6"))
