"""LAC, the Langevin Actor-Critic (docs/spec.md): its config, algorithm, learner, module and the
Langevin chain of Algorithm 1 (``langevin.py``, plain torch). Import the classes from their modules,
or from ``lac_rllib`` (which loads them lazily, so importing the chain alone never loads RLlib)."""
