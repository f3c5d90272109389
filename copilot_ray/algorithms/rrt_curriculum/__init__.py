"""The classical-planner curriculum (``algorithm: rrt_curriculum``): CO-PILOT's traversal and agent on
sub-goal trees cut from RRT* paths, with no learned planner."""
