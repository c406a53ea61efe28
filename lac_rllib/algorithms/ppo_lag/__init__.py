"""PPO-Lagrangian = the on-policy base of constrained/ (on_policy*.py, cost_gae.py) + the Lagrange
multiplier (constrained/lagrangian_learner.py) + PPO's clip: OmniSafe's PPOLag by default, the
paper's PPO-L (safety-starter-agents) as the ``ssa`` preset. FOCOPS, CUP and RESPO build on it."""
