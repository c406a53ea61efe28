"""TRPO-Lagrangian = the trust-region base (families/trust_region/: one trust-region step of
the policy per iteration, Schulman et al. 2015) + the Lagrange multiplier
(families/on_policy/lagrangian.py); OmniSafe's TRPOLag by default, the paper's source
(safety-starter-agents) as the ``ssa`` preset."""
