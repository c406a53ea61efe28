"""SAC-Lagrangian, our off-policy baseline after OmniSafe's SACLag: its config, algorithm, learner,
module and actor network, on the off-policy base (the replay buffer, one update call per iteration:
lac_rllib/families/off_policy/) and the shared cost column (lac_rllib/constrained/costs.py)."""
