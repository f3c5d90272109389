"""SGT-PG (sub-goal tree policy gradient) as a sweep algorithm: the planner pi_p of CO-PILOT trained alone
on the fixed Euclidean + collision cost (no agent), run and scored as a motion planner, as in its paper.

Modules: `settings` (no Ray), `config` (SGTPGConfig, no Ray), `trial` (SGTPGTrial, a Tune Trainable).
The planner and Algorithm 1 are `copilot_ray.planning`'s, unchanged.
"""
