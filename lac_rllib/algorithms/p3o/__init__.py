"""P3O (Zhang et al. 2022) on PPO-Lag's house: PPO's clipped loss plus an exact penalty on the
cost surrogate, no multiplier; OmniSafe's P3O (the paper ran it with its defaults, App. D)."""
