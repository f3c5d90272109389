"""CO-PILOT as an RLlib Algorithm.

    from copilot_ray.algorithms.copilot.algorithm import CoPilot, CoPilotConfig

Modules: `settings` (every setting declared once, the presets; no Ray), `algorithm` (CoPilotConfig and
CoPilot), `traversal_env` (one sub-task = one RLlib episode), `agent_updates` (replay and SAC updates),
`diagnostics` (why a run does or does not learn). Nothing is imported here, so that a sweep spec can be
checked against `settings` without importing Ray.
"""
