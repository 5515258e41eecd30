"""Helpers shared by the test modules (no test module imports another):

* :mod:`support.paths` - the repository, the test tree, the venv's executables;
* :mod:`support.domains` - the ROS domains a test session may use, locked per domain;
* :mod:`support.bags` - the session's recorded runs (conftest's ``bag``),
  bags read and written independently of winder's reader;
* :mod:`support.cell` - running a cell (``winder run``), the small job, a stand-in profile node;
* :mod:`support.ros_probe` - a probe node's service calls to a running cell;
* :mod:`support.cli` - a ``winder`` command and its one-line errors;
* :mod:`support.oracles` - reference computations shared by several modules
  (ruckig's stops, the motor's step responses).

Fixtures live in ``test/conftest.py``; these are plain functions and classes.
"""
