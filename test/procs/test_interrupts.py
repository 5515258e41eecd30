"""winder.interrupts: SIGINT, SIGTERM and SIGHUP as one KeyboardInterrupt in the main
thread, deferred while held, none during the cleanup. Real signals, sent to
this process with os.kill; no ROS."""

from __future__ import annotations

import os
import signal
import time

import pytest

from winder.interrupts import Interrupts


def _deliver(sig: int) -> None:
    """Send ``sig`` to this process and give the main thread a bytecode to run its handler on."""
    os.kill(os.getpid(), sig)
    for _ in range(1000):  # not a wait on an event: the handler raises in one of these
        time.sleep(0.0001)


@pytest.mark.usefixtures("hangup_taken")
@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM, signal.SIGHUP])
def test_a_signal_is_a_keyboard_interrupt_and_the_handlers_come_back(sig: int) -> None:
    before = signal.getsignal(sig)
    interrupts = Interrupts().install()
    try:
        with pytest.raises(KeyboardInterrupt):
            _deliver(sig)
    finally:
        interrupts.restore()
    assert signal.getsignal(sig) is before


def test_a_signal_inside_a_held_section_raises_as_it_ends() -> None:
    interrupts = Interrupts().install()
    steps = []
    try:
        with pytest.raises(KeyboardInterrupt):
            with interrupts.held():
                _deliver(signal.SIGINT)
                steps.append("after the signal")  # the section runs to its end
                with interrupts.held():  # nested: only the outermost end raises
                    steps.append("inner")
                steps.append("after the inner section")
            steps.append("never")
    finally:
        interrupts.restore()
    assert steps == ["after the signal", "inner", "after the inner section"]


def test_every_signal_raises_until_the_cleanup_began() -> None:
    """A second Ctrl-C ends the command too (should the first have been
    swallowed by code that ran Python callbacks); none once the cleanup began."""
    interrupts = Interrupts().install()
    try:
        with pytest.raises(KeyboardInterrupt):
            _deliver(signal.SIGTERM)
        with pytest.raises(KeyboardInterrupt):
            _deliver(signal.SIGINT)
        with pytest.raises(KeyboardInterrupt), interrupts.held():
            _deliver(signal.SIGINT)
        assert not interrupts.pending  # raised once, as the section ended
        interrupts.ending()
        _deliver(signal.SIGTERM)  # the cleanup began: ignored
        _deliver(signal.SIGINT)
    finally:
        interrupts.restore()


def test_a_held_section_left_by_an_error_keeps_the_error() -> None:
    interrupts = Interrupts().install()
    try:
        with pytest.raises(ValueError, match="bad"), interrupts.held():
            _deliver(signal.SIGINT)
            raise ValueError("bad")
        assert interrupts.pending and not interrupts.closing
    finally:
        interrupts.restore()


@pytest.mark.usefixtures("hangup_taken")
@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM, signal.SIGHUP])
def test_deferred_raises_once_its_section_has_run_and_ignored_not_at_all(sig: int) -> None:
    """deferred(): the section runs to its end, the signal raises after it;
    ignored(): the signal is dropped; the handlers before either are back."""
    from winder.interrupts import deferred, ignored

    before = signal.getsignal(sig)
    steps = []
    with pytest.raises(KeyboardInterrupt), deferred():
        _deliver(sig)
        steps.append("after the signal")
    assert steps == ["after the signal"]
    assert signal.getsignal(sig) is before
    with ignored():
        _deliver(sig)
        steps.append("ignored")
    assert steps[-1] == "ignored"
    assert signal.getsignal(sig) is before
