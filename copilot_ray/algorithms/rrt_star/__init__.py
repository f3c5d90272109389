"""RRT* (OMPL) as a sweep algorithm: the motion-planning reference of the paper's Fig. 4b/4c.

Modules: `settings` (no Ray), `config` (RRTStarConfig, no Ray), `trial` (RRTStarTrial, a Tune
Trainable). The planner itself is `copilot_ray.planning.rrt_star`.
"""
