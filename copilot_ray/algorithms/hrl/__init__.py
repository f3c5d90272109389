"""Hierarchical RL in the HIRO style (Nachum et al. 2018, "Data-Efficient Hierarchical Reinforcement
Learning"): the paper's "hierarchical RL" baseline, ``algorithm: hrl``.

What runs:
* a high level observes (observation, final goal) and every ``hrl.c`` env steps proposes a sub-goal as an
  offset in the goal space (the env's ``achieved_goal`` coordinates), each dimension bounded by
  ``hrl.subgoal_range`` x the goal space's width;
* between proposals the goal transition h(s, g, s') = s + g - s' carries it, i.e. the absolute sub-goal
  s_t + g_t stays fixed; the low level acts on (observation, absolute sub-goal[, sub-goal - achieved]
  with ``agent_input: state_goal_delta``, which is HIRO's relative input));
* the low level is rewarded by HIRO's -||s + g - s'|| (``hrl.low_reward: dense``, never terminal) or by the
  goal env's sparse reward for reaching the sub-goal (``sparse``, terminal there);
* the high level learns from (s_t, g, offset, reward_scale x the sum of the goal env's sparse rewards over
  the c steps, s_{t+c}), terminal when the goal was reached, with HIRO's off-policy correction when a
  batch is sampled: the stored offset is replaced by whichever of {it, achieved_{t+c} - achieved_t,
  ``hrl.num_candidates`` draws from N(achieved_{t+c} - achieved_t, (bound / 2)^2)} (clipped to the
  bounds) maximises the *current* low level's log-probability of the segment's stored actions.

Variant and what is left out:
* both levels are SAC (the project's fast goal-conditioned SAC learner, `gc_sac`), not TD3 as in HIRO;
  the correction therefore uses SAC's squashed-Gaussian log-probability instead of TD3's
  -||a - mu(s, g)||^2;
* the goal space is the env's achieved-goal space (the maze: the position; the Ant maze: the torso's
  x, y), not HIRO's first k observation dims; offsets are Euclidean (angle dims, e.g. maze-rigid's, are
  not wrapped);
* no pre-training phase, no separate exploration noise schedules (SAC's own sampling explores; before
  ``num_steps_sampled_before_learning_starts`` both levels act uniformly at random), no reward scaling of
  the low level's intrinsic reward, no hindsight relabelling at either level;
* the high level proposes every c steps even when the sub-goal is reached earlier (as HIRO).

Modules: settings (no Ray), config (HRLConfig, no Ray), hierarchy (h, bounds, correction; numpy),
rollout (lockstep two-level episodes), transitions (replay rows of each level), buffer (the high
level's segment replay), levels (the two SAC learners), algorithm (HRL: loop, evaluation, state),
trial (HRLTrial, a Tune Trainable).
"""
