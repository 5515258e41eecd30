"""Every number and name a command takes is bounded before any work is sized
from it (issue 53, item 9): each case was an internal error (exit 70), ran
without bound, printed another program's usage, or wrote where it was not
asked to. Each is now one line naming the setting, the value and the allowed
range, exit 2, and the work it would have started is replaced here by a
function that fails, so the refusal is shown to come first.
"""

from __future__ import annotations

import os
import socket
from pathlib import Path

import pytest
from support.paths import ROOT

import winder.record.reader as reader
from winder.cli import commands as cli
from winder.motion.job import MAX_JOB_STEPS, Job

ORTHO_RECT = str(ROOT / "jobs" / "ortho_rect.yaml")


def main(argv: list[str], capsys: pytest.CaptureFixture[str]) -> tuple[int, str, str]:
    code = cli.main(argv)
    out, err = capsys.readouterr()
    return code, out, err


def refused(argv: list[str], capsys: pytest.CaptureFixture[str], starts: str) -> str:
    """``winder argv`` ends with one line on stderr, exit 2, starting ``starts``
    after the command's ``error:``; nothing on stdout. The line."""
    code, out, err = main(argv, capsys)
    lines = err.strip().splitlines()
    assert code == 2 and len(lines) == 1 and "Traceback" not in err, (code, err)
    assert lines[0].startswith(f"winder {argv[0]}: error: {starts}"), lines[0]
    assert not out, out
    return lines[0]


@pytest.fixture
def no_bag_read(monkeypatch: pytest.MonkeyPatch) -> None:
    """Reading a recording fails the test: the options are checked first."""

    def forbidden(*_args: object, **_kwargs: object) -> None:
        raise AssertionError("a recording was read before the options were checked")

    monkeypatch.setattr(reader, "read_run", forbidden)
    monkeypatch.setattr(reader, "read_raw", forbidden)


# -- a layer's share of v_max: exit 70 ------------------------------------------------------------


@pytest.mark.parametrize("share", ["1e-300", "5e-324"])
@pytest.mark.parametrize("command", [["check"], ["run", "--check"]])
def test_a_layer_speed_share_that_would_underflow_the_ramp_is_refused(
    command: list[str], share: str, capsys: pytest.CaptureFixture[str]
) -> None:
    """It was "internal error: ValueError: a_max=0.0 is invalid" (exit 70):
    the layer's acceleration a_max x share^2 is 0.0 in floating point."""
    line = refused([*command, ORTHO_RECT, "--layer-speed", f"1:1={share}"], capsys, "layer_speed: ")
    assert f"share {float(share):g} is invalid: must be in [0.001, 1]" in line


def test_a_first_layer_speed_that_would_underflow_the_ramp_is_refused(
    capsys: pytest.CaptureFixture[str],
) -> None:
    """With a layer_speed share of layer 1 as small, v_max x both was 0.0 (exit 70)."""
    argv = ["run", "--check", "--first-layer-speed", "1e-300", "--layer-speed", "1:1=1e-300"]
    refused(argv, capsys, "first_layer_speed=1e-300 is invalid: must be in [0.001, 1]")


# -- a job's size: winder interp ran for days -----------------------------------------------------


def test_winder_interp_of_a_job_no_cell_runs_in_a_week_is_refused_before_it_is_laid_out(
    capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    def forbidden(*_args: object, **_kwargs: object) -> None:
        raise AssertionError("the job was laid out before its size was bounded")

    monkeypatch.setattr(Job, "_lay_out", forbidden)
    argv = ["interp", "--turns-per-layer", "100000", "--layers", "1000", "--poles", "360"]
    line = refused(
        argv, capsys, "turns_per_layer=100000 x layers=1000 x poles=360 with fork_steps_per_rev=1024"
    )
    assert f"a job may have at most {MAX_JOB_STEPS}" in line
    refused(["run", "--check", *argv[1:]], capsys, "turns_per_layer=100000 x layers=1000 x poles=360")


# -- list settings with an empty item were taken ----------------------------------------------------


@pytest.mark.parametrize(
    ("option", "value", "starts"),
    [
        ("--schedule", ",,,", "schedule=',,,' is invalid: it has an empty item"),
        ("--schedule", "pause@1,", "schedule='pause@1,' is invalid: it has an empty item"),
        ("--coil-overrides", ";;;", "coil_overrides=';;;' is invalid: it has an empty item"),
        ("--coil-overrides", "1:", "coil_overrides: '1:' must be COIL:KEY=VALUE[,KEY=VALUE]: no KEY=VALUE"),
        ("--layer-speed", ";", "layer_speed=';' is invalid: it has an empty item"),
    ],
)
def test_a_list_with_an_empty_item_is_refused(
    option: str, value: str, starts: str, capsys: pytest.CaptureFixture[str]
) -> None:
    refused(["run", "--check", option, value], capsys, starts)


# -- winder identify: exit 70, and numpy's overflow warnings with exit 0 ------------------------------


@pytest.mark.parametrize(
    ("option", "value", "starts"),
    [
        ("--window", "1e308", "window=1e+308 is invalid: must be in (0, 1000] ms"),
        ("--window", "0", "window=0.0 is invalid: must be in (0, 1000] ms"),
        ("--gain", "1e308", "gain=1e+308 is invalid: must be in [1e-06, 1e+06]"),
        ("--gain", "1e-308", "gain=1e-308 is invalid: must be in [1e-06, 1e+06]"),
        ("--gain", "inf", "gain=inf is invalid: must be a finite number in [1e-06, 1e+06]"),
    ],
)
def test_identify_bounds_its_window_and_gain_before_reading_a_recording(
    option: str,
    value: str,
    starts: str,
    tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
    no_bag_read: None,
) -> None:
    refused(["identify", str(tmp_path / "bag"), option, value], capsys, starts)


# -- an empty directory name wrote into the current directory ---------------------------------------


@pytest.mark.parametrize(
    ("argv", "option"),
    [
        (["figures", ""], "outdir"),
        (["analyze", "BAG", "--plots-dir", ""], "plots_dir"),
        (["identify", "BAG", "--plots-dir", ""], "plots_dir"),
        (["export", "BAG", "--csv", ""], "csv"),
        (["bag", "recover", "BAG", "--output", ""], "output"),
        (["resonance", "--plots-dir", ""], "plots_dir"),
        (["tune", "--plots-dir", ""], "plots_dir"),
    ],
)
def test_an_empty_directory_name_is_refused_and_nothing_is_written(
    argv: list[str],
    option: str,
    tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
    monkeypatch: pytest.MonkeyPatch,
    no_bag_read: None,
) -> None:
    monkeypatch.chdir(tmp_path)
    argv = [str(tmp_path / "bag") if a == "BAG" else a for a in argv]
    line = refused(argv, capsys, f"{option}='' is invalid: must be a directory name")
    assert "give . for that" in line
    assert list(tmp_path.iterdir()) == []


# -- winder discovery-server: Fast DDS's 93-line usage ------------------------------------------------


@pytest.fixture
def no_server(monkeypatch: pytest.MonkeyPatch) -> None:
    """Starting the server fails the test: its settings are checked first."""

    def forbidden(*_args: object) -> None:
        raise AssertionError("the discovery server was started")

    monkeypatch.setattr(os, "execve", forbidden)


@pytest.mark.parametrize(
    ("argv", "starts"),
    [
        (["--address", "127.0.0.1", "--port", "22"], "port=22 is invalid: must be in [1025, 65535]"),
        (["--port", "1024"], "port=1024 is invalid: must be in [1025, 65535]"),
        (["--port", "65536"], "port=65536 is invalid: must be in [1025, 65535]"),
        (["--id", "256"], "id=256 is invalid: must be in [0, 255]"),
        (["--address", "localhost"], "address='localhost' is invalid: must be an IPv4 address of this host"),
        (["--address", "224.0.0.1"], "address=224.0.0.1 is invalid: a multicast or broadcast address"),
        (["--address", "255.255.255.255"], "address=255.255.255.255 is invalid: a multicast or broadcast"),
        # TEST-NET-3 (RFC 5737): never an address of this host
        (["--address", "203.0.113.7"], "address=203.0.113.7 is invalid: no interface of this host has it"),
    ],
)
def test_the_discovery_server_s_settings_are_checked_before_it_starts(
    argv: list[str], starts: str, capsys: pytest.CaptureFixture[str], no_server: None
) -> None:
    refused(["discovery-server", *argv], capsys, starts)


def test_a_port_in_use_is_refused_before_the_server_starts(
    capsys: pytest.CaptureFixture[str], no_server: None
) -> None:
    """The server itself said so in three lines of its log, and exited 1."""
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as taken:
        taken.bind(("127.0.0.1", 0))
        port = taken.getsockname()[1]
        assert port >= 1025
        for address in ("127.0.0.1", "0.0.0.0"):
            line = refused(
                ["discovery-server", "--address", address, "--port", str(port)],
                capsys,
                f"port={port} is invalid",
            )
            assert f"UDP port {port} on {address} is in use" in line and "[1025, 65535]" in line


def test_a_free_port_of_this_host_starts_the_server(
    capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    """The check refuses only what the server cannot serve: a free port on
    this host's loopback address reaches the server's start (replaced here)."""
    started: list[list[str]] = []

    class Started(BaseException):  # past the command's own handling of errors
        pass

    def execve(_path: str, argv: list[str], _env: dict[str, str]) -> None:
        started.append(argv)
        raise Started

    monkeypatch.setattr(os, "execve", execve)
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as probe:
        probe.bind(("127.0.0.1", 0))
        port = probe.getsockname()[1]  # free again when the probe closes
    with pytest.raises(Started):
        cli.main(["discovery-server", "--address", "127.0.0.1", "--port", str(port)])
    out, _ = capsys.readouterr()
    assert started[0][-4:] == ["-l", "127.0.0.1", "-p", str(port)]
    assert f"on 127.0.0.1:{port}" in out
