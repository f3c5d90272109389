"""What describes and runs a sweep trial, in one place.

- `description`: what a trial is, read off its flat Tune config (spec, settings, labels); no Ray.
- `spec_trial`: `SpecTrial`, the mixin that makes an RLlib Algorithm a trial (each algorithm's
  `trial.py` pairs it with the algorithm: `class CoPilotTrial(SpecTrial, CoPilot)`).
- `planning_trial`: `PickledStateTrial` and `PlanningTrial`, the Tune Trainables of the algorithms that
  are not RLlib's (the planner baselines, HRL).

Nothing is imported here, so `description` can be read without Ray.
"""
