"""copilot_ray: CO-PILOT on Ray RLlib."""

__version__ = "0.1.0"
