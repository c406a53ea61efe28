"""P3O (Zhang et al. 2022) = the on-policy base (families/on_policy/) + an exact penalty on the
cost surrogate, no multiplier; OmniSafe's P3O (the paper ran it with its defaults, App. D)."""
