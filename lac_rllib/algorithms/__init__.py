"""The algorithms, one folder each (RLlib's ``ray/rllib/algorithms/<name>/`` convention): config,
algorithm, learner and module side by side. What they share lives in ``lac_rllib.constrained``."""
