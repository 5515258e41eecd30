"""winder core library: the ROS-free mathematics of the winding cell.

Modules: :mod:`winder.motion.interp` (minimum-deviation interpolation), :mod:`winder.motion.job`
(winding jobs), :mod:`winder.motion.profile` (velocity ramping and step timing),
:mod:`winder.axis` (stepper motor model). All quantities are SI unless a name
says otherwise (``_steps`` for integer step counts).
"""

#: winder's version, written here only: the package metadata reads it (pyproject.toml,
#: src/setup.cfg); ``winder --version`` prints it, every bag's metadata.yaml and every
#: final report carry it (``winder_version``)
__version__ = "0.1.0"
