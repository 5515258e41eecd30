"""winder core library: the ROS-free mathematics of the winding cell.

Modules: :mod:`winder.motion.interp` (minimum-deviation interpolation), :mod:`winder.motion.job`
(winding jobs), :mod:`winder.motion.profile` (velocity ramping and step timing),
:mod:`winder.axis` (stepper motor model). All quantities are SI unless a name
says otherwise (``_steps`` for integer step counts).
"""

__version__ = "0.1.0"
