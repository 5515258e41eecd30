"""The ``winder`` command (``winder --help`` lists every subcommand: run, ctl, analyze, play, tune...)."""

from winder.cli.commands import main

__all__ = ["main"]
