"""Stage 6, timing: the feed sequences (``schedule``), their time-optimal path parametrisation
(``topp``), the feed planner (``feed_planner``) with its optional third-order programme
(``third_order``), and the rapids and S-curve profiles (``timing``).
"""
