"""CUP (Yang et al. 2022, Constrained Update Projection) on PPO-Lag's house: its config, algorithm
and learner; OmniSafe's CUP with its defaults, as the paper ran it (its App. D)."""
