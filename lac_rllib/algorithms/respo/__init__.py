"""RESPO (Ganai et al. 2023) = PPO-Lag + a reach critic V_p that weighs its policy loss and ν's
step: its config, algorithm, module, learner and the reachability connector; the authors' code
(milanganai.github.io, NeurIPS2023/code/respo.py) by default."""
