"""winder core library: the ROS-free mathematics of the winding cell.

Modules: :mod:`winder.interp` (minimum-deviation interpolation), :mod:`winder.job`
(winding jobs), :mod:`winder.profile` (velocity ramping and step timing),
:mod:`winder.motor` (stepper motor model). All quantities are SI unless a name
says otherwise (``_steps`` for integer step counts).
"""

__version__ = "0.1.0"
