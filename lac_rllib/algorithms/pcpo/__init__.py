"""PCPO (Yang et al. 2020) = CPO with PCPO's step: the reward's trust-region step, then its
projection onto the linearised cost constraint; OmniSafe's PCPO (the paper ran it, App. D) by default."""
