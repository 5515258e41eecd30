"""Motion: what the axes should do, in exact integer steps and exact times.

:mod:`~winder.motion.job` (a winding job and its segments),
:mod:`~winder.motion.interp` (minimum-deviation interpolation, eq. 5/7 deviation),
:mod:`~winder.motion.profile` (S-curve, trapezoid and exponential ramps, step timing, jog;
one module a ramp in :mod:`~winder.motion.ramps`),
:mod:`~winder.motion.retime` (a move changed while it runs),
:mod:`~winder.motion.shaped` (input-shaped moves).
Plain numpy; nothing here knows about ROS, bags or plots.
"""
