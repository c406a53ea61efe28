"""RESPO (Ganai et al. 2023) on PPO-Lag's house: its config, algorithm, module, learner and the
reachability connector; the authors' code (milanganai.github.io, NeurIPS2023/code/respo.py) by
default."""
