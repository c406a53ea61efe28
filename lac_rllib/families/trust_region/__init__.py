"""The trust-region base on the on-policy one: the critics by Adam, the policy by one trust-region
step on the whole batch (step.py: Fisher-vector product, CG, line search)."""
