"""Motion: what the axes should do, in exact integer steps and exact times.

:mod:`~winder.motion.job` (a winding job and its segments),
:mod:`~winder.motion.interp` (minimum-deviation interpolation, eq. 5/7 deviation),
:mod:`~winder.motion.profile` (S-curve, trapezoid and exponential ramps, step timing, jog).
Plain numpy; nothing here knows about ROS, bags or plots.
"""
