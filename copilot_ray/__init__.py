"""copilot_ray: CO-PILOT on Ray RLlib."""

import os

# OpenMP's idle threads spin while they wait for work. Two torch threads on two cores that another
# process also uses then run 10-70x slower than one thread (docs/measured.md, "OpenMP"); waiting
# passively does not. libgomp reads this once, when torch first loads, so it is set on the package's
# import, before anything here imports torch; Ray's worker processes inherit it. A value the user set
# is kept.
os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")
# Ray 2.5x's token authentication writes ~/.ray/auth_token and says so on every start: a local run needs
# neither. Set before anything here imports Ray; Ray's workers inherit it. A value the user set is kept.
os.environ.setdefault("RAY_AUTH_MODE", "disabled")

from copilot_ray.console import leave_out_library_notices  # noqa: E402 - after the environment above

# Ray's and RLlib's known notices (the new API stack, Ray's start, ...) where the library is used from
# Python; train and sweep route them to their console log instead (copilot_ray/console.py).
leave_out_library_notices()

__version__ = "0.1.0"
