"""What the ``winder`` subcommands share: the one-line user error, the
options made from a node's settings and their checked values, the job file
named on the command line, the runner's own settings, the guard around the
ROS imports and the progress bar.

Below every subcommand module (:mod:`winder.cli.commands`, ``ctl``,
``replay``, ``resonance``, ``view``): they import from here, never from
each other's command table.
"""

from __future__ import annotations

import argparse
import contextlib
import sys
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

from winder.errors import BadInputError
from winder.interrupts import Interrupts
from winder.motion.job import FIELD_SPECS, Job
from winder.spec import Spec

__all__ = [
    "CELL_SPECS",
    "Progress",
    "UserError",
    "add_spec_arguments",
    "directory_option",
    "given_values",
    "job_file",
    "job_file_hashed",
    "job_from_args",
    "ros_imports",
    "values_from_args",
]


#: Settings of the cell runner itself (``winder run``), checked like the nodes'.
CELL_SPECS: dict[str, Spec] = {
    "timeout": Spec(
        "timeout", float, 3600.0, "give up after this much wall time", "s", 0.0, 1e7, low_open=True
    ),
    "start_timeout": Spec(
        "start_timeout",
        float,
        60.0,
        "give up if the job has not started after this much wall time (a node missing from the graph)",
        "s",
        0.0,
        1e7,
        low_open=True,
    ),
}


class UserError(BadInputError):
    """An error the user can fix (an option, the install); printed as one line, exit status EXIT_BAD_INPUT."""


@contextlib.contextmanager
def ros_imports(interrupts: Interrupts | None = None) -> Iterator[None]:
    """Around a command's imports of :mod:`winder.ros` (rclpy, the message
    packages): their ImportError is the one-line "not installed" error; with
    ``interrupts``, a Ctrl-C while they load is taken as they end, not
    turned into that error (rclpy's loader reports any failure as an ImportError)."""
    with interrupts.held() if interrupts is not None else contextlib.nullcontext():
        try:
            yield
        except ImportError as exc:
            raise UserError(f"the ROS 2 packages are not installed ({exc}); run 'make demo'") from None


def directory_option(option: str, text: str) -> Path:
    """A directory named on the command line for a command's output. UserError
    (one line) for an empty name: ``Path("")`` is the current directory, and
    the files would land there unasked (``.`` names it)."""
    if text == "":
        raise UserError(
            f"{option}='' is invalid: must be a directory name (an empty one would be the current "
            "directory; give . for that)"
        )
    return Path(text)


def add_spec_arguments(
    parser: argparse.ArgumentParser, specs: dict[str, Spec], title: str, skip: tuple[str, ...] = ()
) -> None:
    """One option per setting. Values stay text here and are checked by their
    Spec afterwards, so a bad one is a one-line error, not an argparse usage dump."""
    group = parser.add_argument_group(title)
    for name, spec in specs.items():
        if name in skip:
            continue
        flag = "--" + name.replace("_", "-")
        # a flag not given is None, as any option not given: a job file's value stands
        if spec.kind is bool and spec.default is False:
            group.add_argument(flag, dest=name, action="store_true", default=None, help=spec.description)
        elif spec.kind is bool:
            group.add_argument(
                "--no-" + name.replace("_", "-"),
                dest=name,
                action="store_false",
                default=None,
                help=f"do not {spec.description}",
            )
        else:
            group.add_argument(
                flag, dest=name, default=None, metavar=spec.kind.__name__.upper(), help=spec.help()
            )


def values_from_args(
    args: argparse.Namespace, specs: dict[str, Spec], base: dict[str, Any] | None = None
) -> dict[str, Any]:
    """The settings given on the command line, checked; the others from
    ``base`` (a job file's, checked already), else their defaults."""
    out = {}
    base = base or {}
    for name, spec in specs.items():
        raw = getattr(args, name, None)
        if raw is None:
            out[name] = base.get(name, spec.default)
        elif isinstance(raw, str):
            out[name] = spec.parse(raw)
        else:
            out[name] = spec.check(raw)
    return out


def given_values(args: argparse.Namespace, specs: dict[str, Spec], base: dict[str, Any]) -> dict[str, Any]:
    """Only the settings given: ``base`` (a job file's section, checked
    already) and the options given on the command line over it, checked;
    no defaults (what a node that runs elsewhere is to be told, keeping its
    own values for the rest)."""
    out = {name: value for name, value in base.items() if name in specs}
    for name, spec in specs.items():
        raw = getattr(args, name, None)
        if raw is not None:
            out[name] = spec.parse(raw) if isinstance(raw, str) else spec.check(raw)
    return out


def job_file(args: argparse.Namespace, *, check_fit: bool = True) -> dict[str, dict[str, Any]]:
    """The settings of the job file named on the command line, per node
    (none: empty): ``interp_node``, ``profile_node`` and ``consumer``."""
    return job_file_hashed(args, check_fit=check_fit)[0]


def job_file_hashed(
    args: argparse.Namespace, *, check_fit: bool = True
) -> tuple[dict[str, dict[str, Any]], str]:
    """:func:`job_file` and the sha256 of the file's bytes ("" without a file)."""
    path = getattr(args, "job_file", None)
    if not path:
        return {"interp_node": {}, "profile_node": {}, "consumer": {}}, ""
    from winder.contract.jobfile import load_job_file_hashed

    return load_job_file_hashed(path, check_fit=check_fit)


def job_from_args(args: argparse.Namespace, base: dict[str, Any] | None = None) -> Job:
    return Job.from_dict(values_from_args(args, FIELD_SPECS, base))


class Progress:
    """A one-line progress bar on stderr (only when stderr is a terminal, or forced)."""

    def __init__(self, total: float, label: str, enabled: bool | None = None) -> None:
        self.total = max(float(total), 1e-300)
        self.label = label
        self.enabled = sys.stderr.isatty() if enabled is None else enabled
        self.t0 = time.monotonic()
        self._last = -1.0

    def update(self, done: float, extra: str = "") -> None:
        if not self.enabled:
            return
        now = time.monotonic()
        if now - self._last < 0.1 and done < self.total:
            return
        self._last = now
        frac = min(1.0, done / self.total)
        bar = "#" * int(30 * frac) + "-" * (30 - int(30 * frac))
        sys.stderr.write(f"\r{self.label} [{bar}] {100 * frac:5.1f}% {extra}")
        sys.stderr.flush()

    def close(self) -> None:
        if self.enabled:
            sys.stderr.write("\n")
            sys.stderr.flush()
