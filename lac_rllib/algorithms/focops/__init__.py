"""FOCOPS (Zhang, Vuong & Ross 2020) on PPO-Lag's house: its config, algorithm and learner;
OmniSafe's FOCOPS by default, the paper's source (ymzhang01/focops) as the ``paper`` preset."""
