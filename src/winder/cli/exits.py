"""The exit status of every ``winder`` command: one table, the same for all.

The "Exit codes" section of docs/RELIABILITY.md shows this table; ``test/cli/test_exit_codes.py``
checks that the two agree and that each class really ends with its code.
"""

from __future__ import annotations

__all__ = [
    "EXIT_ABORTED",
    "EXIT_BAD_INPUT",
    "EXIT_FAILED",
    "EXIT_FAULTED",
    "EXIT_INTERNAL",
    "EXIT_INTERRUPTED",
    "EXIT_NODE_DIED",
    "EXIT_OK",
    "EXIT_OUTPUT",
    "EXIT_TABLE",
]

EXIT_OK = 0
EXIT_FAILED = 1
EXIT_BAD_INPUT = 2
EXIT_ABORTED = 3
EXIT_NODE_DIED = 4
EXIT_OUTPUT = 5
EXIT_FAULTED = 6
#: sysexits.h's EX_SOFTWARE: an internal software error
EXIT_INTERNAL = 70
EXIT_INTERRUPTED = 130

#: code -> (name, when), in the words of docs/RELIABILITY.md
EXIT_TABLE: dict[int, tuple[str, str]] = {
    EXIT_OK: ("ok", "the command did what it was asked; a run ended done, its axes as commanded"),
    EXIT_FAILED: (
        "run failed",
        "a run ended incomplete or with errors, or did not start or finish in time; `winder ctl`: "
        "the cell refused the command; `winder play`: a subscriber did not acknowledge every message",
    ),
    EXIT_BAD_INPUT: (
        "bad input",
        "an option, a job file or a recording that cannot be used, a setting a node of the cell refused, "
        "a namespace where another cell runs; nothing was started or written",
    ),
    EXIT_ABORTED: (
        "run aborted",
        "an operator abort (`winder ctl abort`, the job's schedule) ended the run, the axes at rest, "
        "no error, no fault",
    ),
    EXIT_NODE_DIED: (
        "node died",
        "a node of the cell exited (killed, crashed) before the run ended; its log is named",
    ),
    EXIT_OUTPUT: (
        "output not written",
        "a file or directory the command writes cannot be written (no permission, a file where a "
        "directory should be, no space left); nothing half-written is left",
    ),
    EXIT_FAULTED: (
        "run faulted",
        "a run executed its steps (done, or aborted at rest) but its axes did not do what was "
        "commanded: the simulated axes lost steps or left the wire's path by more than half its "
        "diameter, or the wire's tension left its alarm band; the final report's `faults` says what, "
        "its `state` stays done or aborted",
    ),
    EXIT_INTERNAL: (
        "internal error",
        "a bug in winder, not the input: one line names the exception and the file its traceback was "
        "written to (`$XDG_STATE_HOME/winder/crash/`, by default `~/.local/state/winder/crash/`); "
        "please report it with that file",
    ),
    EXIT_INTERRUPTED: ("interrupted", "Ctrl-C (SIGINT): the cell's nodes were stopped"),
}
