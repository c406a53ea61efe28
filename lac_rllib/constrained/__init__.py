"""What every constrained (safe-RL) algorithm here shares, of no one family: the Lagrange
multiplier, the cost column and episode costs, the safe-task part of a config, the observation
filter, the declared config fields, the result keys, the networks and the fused minibatch loop.
Nothing here imports a family or an algorithm."""
