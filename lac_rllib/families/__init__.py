"""The family bases the algorithms are built on, one folder each, laid out like an algorithm's:
the on-policy base (PPO-Lag, P3O, FOCOPS, CUP, RESPO), the trust-region base on it (TRPO-Lag, CPO,
PCPO) and the off-policy base (SAC-Lag; LAC's algorithm and module). A family imports what every
algorithm shares (lac_rllib/constrained/) and no algorithm."""
