"""CPO (Achiam et al. 2017) on TRPO-Lag's house: the trust-region step of the linearised
constrained problem, no multiplier; OmniSafe's CPO by default, the paper's source
(safety-starter-agents) as the ``ssa`` preset. The house of PCPO."""
