"""The off-policy base: env steps into a replay buffer and one update call over it per iteration
(algorithm.py, config.py), and a module whose networks have Polyak targets (module.py)."""
