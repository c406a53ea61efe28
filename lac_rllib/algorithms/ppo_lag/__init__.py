"""PPO-Lagrangian on RLlib's PPO (new API stack): its config, algorithm, learner, module and the
cost GAE connector; OmniSafe's PPOLag by default, the paper's PPO-L (safety-starter-agents) as the
``ssa`` preset."""
