"""NEXT (neural exploration-exploitation trees, Chen et al., ICLR 2020) as a sweep algorithm: a learned
tree search trained by imitation of RRT* demonstrations and then of its own solved searches, run and
scored as a motion planner like RRT* and SGT-PG.

Modules: `settings` (no Ray), `config` (NEXTConfig, no Ray), `trial` (NEXTTrial, a Tune Trainable).
The planner itself is `copilot_ray.planning.next_planner`.
"""
