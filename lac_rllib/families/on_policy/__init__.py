"""The on-policy base: RLlib's PPO with a cost critic, the cost GAE, the cost window Ĵ_C, PPO's
clipped surrogate and the KL early stop (learner.py), and the multiplier's mixin (lagrangian.py)."""
