"""RLlib's PPO on the flattened goal env (`algorithm: ppo`): the paper's on-policy baseline."""
