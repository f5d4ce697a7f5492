"""The kinematics' numerical tolerances, in a module of their own: both routes (the numpy functions
and the compiled loops of :mod:`._loops`) take them from here."""

#: Below this sin(phi1) the axis is taken as the table normal (theta2 from the caller).
POLE_EPS = 1e-12

#: Relative tolerance on the closure equations (eq. 2) for accepting a root, times L^2.
CLOSURE_TOL = 1e-9

#: Pieces of (-alpha_max, alpha_max) in which eq. 31's roots are counted (full._only_working_root).
ROOT_PIECES = 8
