"""The one error family of winder: what went wrong, named by what the user must do.

Every error winder means a person to read derives from :class:`WinderError`;
its message is one line that names the thing (setting, file, node) and, for a
value, the value and what it must be. The subclasses say who acts:

* :class:`BadInputError` (also a ``ValueError``): a job, setting, option,
  argument or file the user gave cannot be used; they fix it. Its
  subclasses: :class:`winder.spec.SpecError` (a setting out of range), the
  job's, the job file's, a schedule's, ...; :class:`BadBagError`: a
  recording that cannot be read or used.
* :class:`RefusedError`: the cell refused a command (busy, not in a state to
  take it); the input may be fine, the moment is not.
* :class:`UnavailableError`: a node or the cell is not there or does not
  answer in time.
* :class:`OutputError`: a file or directory a command writes cannot be
  written (permission, space, a file where a directory should be).

``ValueError`` stays a base of the input kinds so that callers which reject a
bad value by catching ``ValueError`` (the ROS nodes refuse a parameter and keep
running) keep working. A bare ``ValueError``, ``AssertionError`` or
``RuntimeError`` raised inside winder is an internal check, a bug: the
``winder`` command reports it as an internal error with its traceback saved
(docs/RELIABILITY.md, "Exit codes"), never as the user's mistake.

The lowest layer of the library: it imports nothing of winder (and nothing
but the standard library), so any module may raise these.
"""

from __future__ import annotations

__all__ = [
    "BadBagError",
    "BadInputError",
    "OutputError",
    "RefusedError",
    "UnavailableError",
    "WinderError",
]


class WinderError(Exception):
    """Any error winder reports to a person: one line, its reason."""


class BadInputError(WinderError, ValueError):
    """A job, setting, option, argument or input file cannot be used: the user fixes it.
    The message names it, its value and what it must be."""


class BadBagError(BadInputError):
    """A recording cannot be read or used (not a bag, damaged, not a winder run);
    the message names the file and why."""


class RefusedError(WinderError):
    """The cell refused a command (its state does not allow it now); the message is its reason."""


class UnavailableError(WinderError):
    """A node or the cell is not there or did not answer in time; the message names what was waited for."""


class OutputError(WinderError):
    """A file or directory a command writes cannot be written; the message
    is one line naming it and the reason."""
