"""copilot_ray: CO-PILOT on Ray RLlib."""

import os

# OpenMP's idle threads spin while they wait for work. Two torch threads on two cores that another
# process also uses then run 10-70x slower than one thread (docs/measured.md, "OpenMP"); waiting
# passively does not. libgomp reads this once, when torch first loads, so it is set on the package's
# import, before anything here imports torch; Ray's worker processes inherit it. A value the user set
# is kept.
os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")

__version__ = "0.1.0"
