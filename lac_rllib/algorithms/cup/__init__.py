"""CUP (Yang et al. 2022, Constrained Update Projection) = PPO-Lag + a projection stage in the same
update; OmniSafe's CUP with its defaults, as the paper ran it (its App. D)."""
