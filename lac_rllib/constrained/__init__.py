"""What every constrained (safe-RL) algorithm here shares: the Lagrange multiplier, the cost
column and episode costs, the safe-task part of a config, the observation filter, the declared
config fields and the result keys. Nothing here imports an algorithm."""
