"""The ``winder`` command: ``run``, ``interp``, ``analyze``, ``identify``, ``bag``, ``figures``."""

from winder.cli.commands import main

__all__ = ["main"]
