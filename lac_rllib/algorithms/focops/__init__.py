"""FOCOPS (Zhang, Vuong & Ross 2020) = PPO-Lag with FOCOPS's policy loss in place of PPO's clip;
OmniSafe's FOCOPS by default, the paper's source (ymzhang01/focops) as the ``paper`` preset."""
