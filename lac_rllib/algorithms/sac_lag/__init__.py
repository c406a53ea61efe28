"""SAC-Lagrangian, our off-policy baseline after OmniSafe's SACLag: its config, algorithm, learner,
module and actor network, on LAC's skeleton (the replay buffer, the cost column, one update call per
iteration: lac_rllib/constrained/)."""
