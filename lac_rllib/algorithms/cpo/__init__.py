"""CPO (Achiam et al. 2017) = the trust-region base (families/trust_region/) + CPO's step of
the linearised constrained problem, no multiplier; OmniSafe's CPO by default, the paper's source
(safety-starter-agents) as the ``ssa`` preset. PCPO builds on it."""
