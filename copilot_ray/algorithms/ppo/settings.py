"""Every setting of the PPO baseline (``algorithm: ppo``), declared once.

RLlib's PPO, its documented defaults (``PPOConfig``) unless a spec sets them, on the goal env flattened
to one Box observation (observation + goal, and goal - achieved with the default ``agent_input``), one
training task (s0, g) per episode of ``tau_max`` steps, rewarded like every other agent here (the goal
env's sparse reward times ``reward_scale``; ``agent_collision``). Evaluation: the same test tasks and
step budget as SAC, HER, SoRB and CO-PILOT, with the Gaussian's mean (clipped) or a sample.
"""

from __future__ import annotations

from copilot_ray.algorithms.sac import settings as sac_settings
from copilot_ray.algorithms.sac.settings import AGENT
from copilot_ray.settings import float_setting, int_setting

# The agent-side settings shared with the SAC baselines (not SAC's own learning settings).
_SHARED = ("tau_max", "reward_scale", "agent_collision", "agent_collision_penalty", "agent_input")
_EVALUATION = ("eval_interval", "eval_every_env_steps", "eval_num_tasks", "eval_action")
TASK = [s for s in AGENT if s.key in _SHARED + _EVALUATION]

# RLlib's PPOConfig defaults (ray 2.x, new API stack), so a spec can sweep them.
TRAINING = [
    float_setting("lr", "training", 5e-5, "Adam learning rate", 0.0, lo_open=True),
    float_setting("gamma", "training", 0.99, "discount", 0.0, 1.0),
    float_setting("lambda_", "training", 1.0, "GAE lambda", 0.0, 1.0),
    float_setting("clip_param", "training", 0.3, "PPO's ratio clip", 0.0, lo_open=True),
    float_setting("entropy_coeff", "training", 0.0, "entropy bonus", 0.0),
    float_setting("vf_loss_coeff", "training", 1.0, "value loss weight", 0.0),
    int_setting(
        "train_batch_size_per_learner", "training", 4000, "env steps per PPO update (one iteration)", 1
    ),
    int_setting("minibatch_size", "training", 128, "SGD minibatch", 1),
    int_setting("num_epochs", "training", 30, "passes over each batch", 1),
]
SETTINGS = {s.key: s for s in (*TASK, *TRAINING)}
# What a comparison tunes for PPO (`search: declared`): rl-zoo's usual suspects for sparse rewards; the
# defaults (RLlib's) lie inside and are tried first.
SEARCH_SPACE: dict[str, dict] = {
    "lr": {"float": [5e-5, 1e-3], "log": True},
    "entropy_coeff": {"float": [0.0, 0.01]},
    "lambda_": {"categorical": [0.9, 0.95, 1.0]},
    "gamma": {"categorical": [0.98, 0.99, 0.995]},
}
# An RLlib learner: on the trial's GPU share when the spec asks for one (resources.gpus_per_trial).
GPU_LEARNER = True

METRICS = sac_settings.METRICS  # the same figures as the SAC baseline's


def max_iteration_env_steps(values) -> int:
    """One iteration: one PPO batch of env steps."""
    return int(values.get("train_batch_size_per_learner", SETTINGS["train_batch_size_per_learner"].default))


def combination_problems(values):
    """A minibatch larger than the batch cannot be drawn."""
    batch = values.get("train_batch_size_per_learner", 4000)
    mini = values.get("minibatch_size", 128)
    if isinstance(batch, int) and isinstance(mini, int) and mini > batch:
        return [
            (
                ("minibatch_size", "train_batch_size_per_learner"),
                {"minibatch_size": mini, "train_batch_size_per_learner": batch},
                "the minibatch must fit in the batch",
            )
        ]
    return []
