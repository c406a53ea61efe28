"""TRPO-Lagrangian = the trust-region base (constrained/trust_region_*.py: one trust-region step of
the policy per iteration, Schulman et al. 2015) + the Lagrange multiplier
(constrained/lagrangian_learner.py); OmniSafe's TRPOLag by default, the paper's source
(safety-starter-agents) as the ``ssa`` preset."""
