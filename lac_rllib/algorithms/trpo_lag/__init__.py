"""TRPO-Lagrangian (Schulman et al. 2015 with PPO-Lag's multiplier) on PPO-Lag's house: one
trust-region step of the policy per iteration, the house of CPO and PCPO; OmniSafe's TRPOLag by
default, the paper's source (safety-starter-agents) as the ``ssa`` preset."""
