"""No input costs minutes or a traceback (issue 41): each is refused in one
line naming the setting, the value and the allowed range or rule, with the
exit status of its class, before any work is sized from it (shown by the
work being replaced with a function that fails, never by a timing).
"""

from __future__ import annotations

import os
import subprocess
import tracemalloc
from pathlib import Path
from typing import Any

import pytest
from support.cli import run_cli as cli_run

from winder.cli import commands as cli

LONG_NS = "/" + "x" * 300


def run_cli(*args: str) -> subprocess.CompletedProcess[str]:
    """``winder *args`` seen from this host only (support.cli.run_cli)."""
    return cli_run(*args, env={**os.environ, "ROS_AUTOMATIC_DISCOVERY_RANGE": "LOCALHOST"})


def one_line(code: int, err: str, want: int = 2) -> str:
    assert "Traceback" not in err, err
    lines = err.strip().splitlines()
    assert code == want and len(lines) == 1, (code, err)
    assert len(lines[0]) < 500, lines[0]
    return lines[0]


def main(argv: list[str], capsys: pytest.CaptureFixture[str]) -> tuple[int, str, str]:
    code = cli.main(argv)
    out, err = capsys.readouterr()
    return code, out, err


# -- 1. turns_per_layer: auto past its range -----------------------------------------------------


@pytest.mark.parametrize("extra", [[], ["--lay", "orthocyclic"], ["--json"]])
def test_winder_check_refuses_auto_turns_past_the_limit(
    extra: list[str], capsys: pytest.CaptureFixture[str]
) -> None:
    argv = ["check", "--turns-per-layer", "auto", "--bobbin.window-width", "10", "--wire-diameter", "1e-5"]
    code, out, err = main(argv + extra, capsys)
    line = one_line(code, err)
    assert line.startswith("winder check: error: turns_per_layer=auto is invalid: 1000000 turns"), line
    assert "[1, 100000]" in line and not out


def test_a_job_file_with_auto_turns_past_the_limit_is_refused_naming_it(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    job = tmp_path / "wide.yaml"
    job.write_text(
        "interp_node:\n  ros__parameters:\n    turns_per_layer: auto\n    lay: orthocyclic\n"
        "    wire_diameter: 1.0e-5\n    bobbin:\n      window_width: 10.0\n"
    )
    for command in (["check"], ["run", "--check"], ["interp"]):
        code, _, err = main([*command, str(job)], capsys)
        line = one_line(code, err)
        assert f"{job}: interp_node: turns_per_layer=auto is invalid: 1000000 turns" in line, line


# -- 2. an orthocyclic window narrower than the lay needs -----------------------------------------

NARROW = """\
interp_node:
  ros__parameters:
    lay: orthocyclic
    turns_per_layer: auto
    wire_diameter: 0.0005
    feed_step: 5.0e-6
    lay.crossover: 30.0
    fork_steps_per_rev: 5120
    layers: 8
    poles: 1
    bobbin:
      window_width: 0.0004
      window_height: 0.005
"""


@pytest.mark.parametrize("extra", [[], ["--json"]])
def test_winder_check_reports_and_refuses_a_window_narrower_than_the_wire(
    extra: list[str], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """0.5 mm wire in a 0.4 mm window, orthocyclic: no layer holds a turn.
    The report, then the overflow in one line, exit 2 (was: IndexError in layer_cam)."""
    job = tmp_path / "narrow.yaml"
    job.write_text(NARROW)
    code, out, err = main(["check", str(job), *extra], capsys)
    line = one_line(code, err)
    assert line == (
        "winder check: error: layer 1 needs 1 turn x 0.5 mm = 0.5 mm, the window is 0.4 mm wide: "
        "0.1 mm over (no turn fits)"
    )
    assert ('"fits": false' if extra else "fits           NO: layer 1 needs 1 turn") in out


def test_winder_check_of_a_shifted_layer_that_holds_no_turn(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """0.3 mm wire in the 0.4 mm window: layer 1 holds a turn, layer 2 (shifted
    by d/2) none: an orthocyclic coil of two layers needs 1.5 wire diameters."""
    job = tmp_path / "narrow.yaml"
    job.write_text(NARROW.replace("0.0005", "0.0003").replace("30.0", "120.0"))
    code, out, err = main(["check", str(job)], capsys)
    line = one_line(code, err)
    assert "layer 2 needs 1 turn x 0.3 mm + 0.15 mm offset = 0.45 mm, the window is 0.4 mm wide" in line
    assert "fits           NO: layer 2 needs 1 turn" in out
    code, _, err = main(["run", "--check", str(job)], capsys)
    assert "layer 2 needs 1 turn" in one_line(code, err)


# -- 4. a namespace ROS would refuse ---------------------------------------------------------------


@pytest.mark.parametrize(
    "argv",
    [
        ["run", "--check"],
        ["view", "--port", "0"],
        ["ctl", "state", "--timeout", "1"],
        ["ctl", "pause", "--timeout", "1"],
    ],
    ids=["run", "view", "ctl state", "ctl pause"],
)
def test_a_300_character_namespace_is_refused_before_rcl_sees_it(argv: list[str]) -> None:
    r = run_cli(*argv, "--namespace", LONG_NS)
    line = one_line(r.returncode, r.stderr)
    assert "namespace='/xxxxxxxx" in line and "(301 characters) is invalid: 301 characters, at most" in line


@pytest.mark.parametrize(
    "argv", [["param", "get", "x" * 300, "rate"], ["lifecycle", "x" * 300, "get"]], ids=["param", "lifecycle"]
)
def test_a_300_character_node_name_is_refused_before_rcl_sees_it(argv: list[str]) -> None:
    """``winder ctl param/lifecycle NODE``: a node whose services ROS could not name."""
    r = run_cli("ctl", *argv, "--timeout", "1")
    line = one_line(r.returncode, r.stderr)
    assert "node='xxxxxxxx" in line and "(300 characters) is invalid" in line, line
    assert "longer than the 247 characters ROS allows a name" in line, line


@pytest.mark.ros
@pytest.mark.parametrize("command", ["play", "resim"])
def test_play_and_resim_refuse_it_too(command: str, bag: Any, tmp_path: Path) -> None:
    extra = ["--bag-dir", str(tmp_path / "b")] if command == "resim" else ["--no-wait"]
    r = run_cli(command, str(bag("lin2k")), "--namespace", LONG_NS, *extra)
    assert "(301 characters) is invalid" in one_line(r.returncode, r.stderr)
    assert not (tmp_path / "b").exists()


# -- 5. a huge winder interp ------------------------------------------------------------------------


def test_winder_interp_streams_a_long_layer_in_flat_memory(capsys: pytest.CaptureFixture[str]) -> None:
    """A layer of 2^25 steps: made whole it took 1.3 GB (a layer of 2^31
    steps: an ArrayMemoryError); made and measured a block at a time, far less."""
    argv = ["interp", "--turns-per-layer", "32768", "--layers", "1", "--poles", "1"]
    tracemalloc.start()
    try:
        code, out, err = main(argv, capsys)
        _, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    assert code == 0, err
    assert f"steps              {32768 * 1024}  (" in out
    assert "mean deviation     2.500 um" in out
    assert peak < 300 * 2**20, f"{peak / 2**20:.0f} MiB"


def test_winder_interp_of_an_orthocyclic_job_measures_the_cam(capsys: pytest.CaptureFixture[str]) -> None:
    """Each layer against its path (the cam's pieces), as winder analyze does:
    the holds and crossovers of the flyer's cam, not its net line."""
    root = Path(__file__).resolve().parents[2]
    code, out, err = main(["interp", str(root / "jobs" / "ortho_round.yaml")], capsys)
    assert code == 0, err
    mean = float(out.split("mean deviation")[1].split()[0])
    assert 0 < mean < 1.25  # below a quarter feed step (5 um / 4): the cam holds each turn exactly


def test_the_one_turn_comparison_of_a_fine_feed_is_bounded(capsys: pytest.CaptureFixture[str]) -> None:
    argv = ["interp", "--feed-step", "1e-9", "--turns-per-layer", "1", "--layers", "1", "--poles", "1"]
    code, out, err = main(argv, capsys)
    assert code == 0, err
    assert "one turn, 2500000 feed x 1024 fork steps, mean deviation" in out
    argv = ["interp", "--feed-step", "5e-10", "--turns-per-layer", "1", "--layers", "1", "--poles", "1"]
    code, out, err = main(argv, capsys)
    assert code == 0, err
    assert "one turn, 5000000 feed x 1024 fork steps: not compared (more than 4194304 steps" in out


# -- beyond the list --------------------------------------------------------------------------------


def test_a_bag_dir_with_a_name_no_file_system_takes(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    for bag_dir in (tmp_path / ("x" * 300), tmp_path / "a" / ("x" * 300)):
        code, _, err = main(["run", "--check", "--bag-dir", str(bag_dir)], capsys)
        line = one_line(code, err)
        assert line.startswith("winder run: error: bag_dir=") and "longer than 255 bytes" in line
    deep = tmp_path / "/".join(["y" * 200] * 20)
    code, _, err = main(["run", "--check", "--bag-dir", str(deep)], capsys)
    assert "bytes long, at most" in one_line(code, err)
    assert list(tmp_path.iterdir()) == []


def test_a_foxglove_host_that_does_not_resolve_fails_the_check(capsys: pytest.CaptureFixture[str]) -> None:
    code, _, err = main(["run", "--check", "--foxglove", "0", "--foxglove-host", ""], capsys)
    assert one_line(code, err).startswith(
        "winder run: error: --foxglove-host='' is invalid: cannot be resolved"
    )


def test_outputs_are_checked_before_a_long_computation(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    """winder resonance and tune write their figures and table after minutes
    of simulation: a place they cannot be written is refused first (exit 5)."""
    import winder.analysis.resonance as resonance
    import winder.analysis.tune as tune

    def forbidden(*_a: object, **_k: object) -> None:
        raise AssertionError("simulated before the outputs were checked")

    monkeypatch.setattr(resonance, "residual_table", forbidden)
    monkeypatch.setattr(tune, "tune", forbidden)
    (tmp_path / "file").write_text("")
    for argv in (
        ["resonance", "--plots-dir", str(tmp_path / "file" / "plots")],
        ["resonance", "--no-plots", "--json", str(tmp_path / ("x" * 300) / "t.json")],
        ["resonance", "--no-plots", "--json", str(tmp_path)],
        ["resonance", "--plots-dir", str(tmp_path / ("x" * 300))],
        ["tune", "--plots-dir", str(tmp_path / ("x" * 300))],
    ):
        code, _, err = main(argv, capsys)
        assert one_line(code, err, want=5).startswith(f"winder {argv[0]}: error: "), argv
    assert sorted(p.name for p in tmp_path.iterdir()) == ["file"]


def test_figures_into_a_name_too_long(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    code, _, err = main(["figures", str(tmp_path / ("x" * 300))], capsys)
    assert "cannot be made a directory" in one_line(code, err, want=5)


def test_resonance_holds_its_damping_ratios_to_a_few(capsys: pytest.CaptureFixture[str]) -> None:
    code, _, err = main(["resonance", "--no-plots", "--zetas", ",".join(["0.1"] * 9)], capsys)
    assert "9 damping ratios, at most 8" in one_line(code, err)


def test_tune_refuses_a_move_too_long_to_simulate_before_simulating(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    """A layer of 1.3*10^9 steps: tune simulated it whole and was killed for its memory."""
    import winder.analysis.tune as tune

    def forbidden(*_a: object, **_k: object) -> None:
        raise AssertionError("simulated before the job's moves were bounded")

    monkeypatch.setattr(tune, "lost_steps", forbidden)
    job = tmp_path / "long.yaml"
    job.write_text(
        "interp_node:\n  ros__parameters:\n    turns_per_layer: 20000\n    fork_steps_per_rev: 65536\n"
        "    poles: 1\n    layers: 1\nprofile_node:\n  ros__parameters:\n    v_max: 1.0e7\n"
        "    a_max: 1.0e10\n    j_max: 1.0e14\n"
    )
    code, _, err = main(["tune", str(job), "--no-plots"], capsys)
    line = one_line(code, err)
    assert "a layer of 1310720000 steps is too long to tune" in line and "at most 2097152" in line


@pytest.mark.ros
def test_the_interp_node_refuses_auto_turns_past_the_limit_set_live(procs: Any, ros: Any) -> None:
    """Set live on a running interp node (it froze for over 300 s): refused
    in one line naming it, the node answers the next call."""
    from support.ros_probe import set_params

    p = procs.start("interp_node", "-p", "autostart:=false")
    results = set_params(
        ros, "interp_node", {"wire_diameter": 1e-5, "bobbin.window_width": 10.0, "turns_per_layer": "auto"}
    )
    assert [r.successful for r in results] == [True, True, False], [r.reason for r in results]
    reason = results[2].reason
    assert "\n" not in reason and "turns_per_layer=auto is invalid: 1000000 turns" in reason, reason
    assert "[1, 100000]" in reason
    [again] = set_params(ros, "interp_node", {"turns_per_layer": 40})
    assert again.successful, again.reason
    assert p.poll() is None and "Traceback" not in procs.log(p)
