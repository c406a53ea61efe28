"""PPO-Lagrangian = the on-policy base (families/on_policy/: its learner, cost GAE) + the Lagrange
multiplier (families/on_policy/lagrangian.py) + PPO's clip: OmniSafe's PPOLag by default, the
paper's PPO-L (safety-starter-agents) as the ``ssa`` preset. FOCOPS, CUP and RESPO build on it."""
