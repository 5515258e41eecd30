"""winder.analysis.metrics and ``winder analyze`` on bags written by the real nodes.

Every expected value is worked out here from the bag as rosbags reads it, or
from a closed form: eq. 7 with a plain loop over the step rows, the peak
velocities of the S-curve from its distance equation, the exponential ramp's
initial acceleration, the tracking error from the joint topics, the slips from
the final position error and the tooth pitch.
"""

from __future__ import annotations

import json
import math
import shutil
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import test_reader
from conftest import final_report, rosbags_read
from test_reader import joint_arrays, run_cli, step_rows

from winder.analysis.metrics import analyze, step_kinematics
from winder.record.reader import read_run

pytestmark = pytest.mark.ros

V_MAX, A_MAX, J_MAX, TAU = (
    2048.0,
    8192.0,
    65536.0,
    0.1,
)  # the profile node's defaults (steps of the major axis)


@pytest.fixture(scope="session")
def bag(tmp_path_factory: pytest.TempPathFactory, request: pytest.FixtureRequest) -> Any:
    """The bags shared with test_reader (one ``winder run`` per configuration per session)."""
    return test_reader.bags(tmp_path_factory, request).get


def eq7_by_hand(path: Path) -> tuple[float, float, list[float]]:
    """Mean and max distance of every commanded step of every layer to its line
    (eq. 5 and 7 of the 2016 paper), and the mean per turn, from the raw bag."""
    ref = rosbags_read(path)
    ns = next(k for k in ref if k.endswith("/winder/job"))[: -len("/winder/job")]
    job = json.loads(ref[f"{ns}/winder/job"][0][1].data)
    rows = step_rows(ref[f"{ns}/winder/step_times"])
    lx, ly = job["step_lengths"][0], job["step_lengths"][1]
    spr = job["job"]["fork_steps_per_rev"]
    dists: list[float] = []
    per_turn: list[float] = []
    for i, seg in enumerate(job["segments"]):
        if seg["kind"] != "layer":
            continue
        dx, dy = seg["delta"][0], seg["delta"][1]
        turns: dict[int, list[float]] = {}
        for row in rows[rows[:, 1] == i]:
            x = (int(row[2]) - seg["start"][0]) * lx  # m of feed
            y = (int(row[3]) - seg["start"][1]) * ly  # m of flyer arc
            xe, ye = dx * lx, dy * ly
            d = abs(xe * y - x * ye) / math.sqrt(xe * xe + ye * ye)
            dists.append(d)
            turn = max(0, math.ceil((int(row[3]) - seg["start"][1]) / spr) - 1)
            turns.setdefault(turn, []).append(d)
        per_turn += [sum(v) / len(v) for _, v in sorted(turns.items())]
    return sum(dists) / len(dists), max(dists), per_turn


def test_eq7_of_the_commanded_steps(bag: Any) -> None:
    for name in ("lin2k", "nlns"):
        path = bag(name)
        res = analyze(read_run(path))
        mean, worst, per_turn = eq7_by_hand(path)
        assert res.command.mean == pytest.approx(mean, rel=1e-12)
        assert res.command.max == pytest.approx(worst, rel=1e-12)
        wire = 2.5e-3
        assert res.command.turn_max_pct == pytest.approx(100 * max(per_turn) / wire, rel=1e-12)
        assert res.command.turn_mean_pct == pytest.approx(100 * np.mean(per_turn) / wire, rel=1e-12)
        # the README's claim: minimum deviation = a quarter of the 10 um feed step, 0.1 % of the wire
        assert res.command.mean == pytest.approx(2.5e-6, rel=2e-3)
        assert res.command.turn_max_pct == pytest.approx(0.1, rel=5e-3)


def test_eq7_of_the_simulated_axes(bag: Any) -> None:
    """The axes' deviation, by hand: each sample taken while a layer is wound
    belongs to the nearest layer segment (clipped, in metres) and is measured
    perpendicular to that segment's line (eq. 5): an axis that overshoots the
    end of the last layer along the line is on the line."""
    path = bag("lin2k")
    res = analyze(read_run(path))
    ref = rosbags_read(path)
    job = json.loads(ref["/winder/job"][0][1].data)
    rows = step_rows(ref["/winder/step_times"])
    t, pos, _ = joint_arrays(ref["/winder/joint_states"])
    lx, ly = job["step_lengths"][0], job["step_lengths"][1]
    js = job["joint_step"]
    layers = [s for s in job["segments"] if s["kind"] == "layer"]
    # a sample is taken while winding if the last step before it belongs to a layer
    last = np.searchsorted(rows[:, 0], np.round(t * 1e9).astype(np.int64), side="right") - 1
    kinds = [s["kind"] for s in job["segments"]]
    winding = [k >= 0 and kinds[rows[k, 1]] == "layer" for k in last]
    px = pos[winding, 0] / js[0] * lx
    py = pos[winding, 1] / js[1] * ly
    nearest = np.full(px.size, np.inf)
    dist = np.zeros(px.size)
    for s in layers:
        ax, ay = s["start"][0] * lx, s["start"][1] * ly
        ex, ey = s["delta"][0] * lx, s["delta"][1] * ly
        u = np.clip(((px - ax) * ex + (py - ay) * ey) / (ex * ex + ey * ey), 0, 1)
        clipped = np.hypot(px - (ax + u * ex), py - (ay + u * ey))
        closer = clipped < nearest
        nearest = np.where(closer, clipped, nearest)
        dist = np.where(closer, np.abs(ex * (py - ay) - (px - ax) * ey) / math.hypot(ex, ey), dist)
    assert res.actual is not None
    assert res.actual.points == px.size
    assert res.actual.mean == pytest.approx(dist.mean(), rel=1e-9)
    assert res.actual.max == pytest.approx(dist.max(), rel=1e-9)
    # the axes smooth the staircase: they deviate less than the commanded steps
    assert res.actual.mean < res.command.mean


def test_step_kinematics_of_a_constant_acceleration() -> None:
    """Steps of x = v0 t + a t^2 / 2, at the roots t_k of x = k: v = v0 + a t,
    acceleration a, jerk 0. Central differences over a stride of m steps are
    off by about (a m / v^2)^2 / 2 in speed (the speed changes within the
    stencil); the ns rounding of the step times adds noise to the acceleration
    (~2 ns v^3 / m^2) and more to the jerk."""
    a = 5000.0
    k = np.arange(0, 8001)
    for v0 in (300.0, 2000.0):
        t, v, acc, j = step_kinematics(np.rint((np.sqrt(v0 * v0 + 2 * a * k) - v0) / a * 1e9))
        assert t.size > 7000
        m = np.ceil(0.002 * v)  # STRIDE_TIME / step interval
        bound = 0.5 * (a * m / v**2) ** 2
        assert np.all(np.abs(v / (v0 + a * t) - 1) <= 2 * bound)
        np.testing.assert_allclose(acc, a, rtol=2e-3)
        assert np.max(np.abs(j)) < 0.2 * a * a / v0
    # from rest t(k) ~ sqrt(k) is singular at k = 0: the stencil keeps 8 strides away,
    # which bounds the error of the speed to 0.2 %
    t, v, acc, _ = step_kinematics(np.rint(np.sqrt(2 * k / a) * 1e9))
    np.testing.assert_allclose(v, a * t, rtol=2e-3)
    np.testing.assert_allclose(acc, a, rtol=6e-3)


def scurve_peak(n: float) -> float:
    """Peak speed of a symmetric S-curve move of n steps from and to rest with
    the default limits: n = V (V/A + A/J) when A is reached (V >= A^2/J)."""
    if n >= V_MAX * (V_MAX / A_MAX + A_MAX / J_MAX):
        return V_MAX
    b = A_MAX / J_MAX
    v = A_MAX / 2 * (-b + math.sqrt(b * b + 4 * n / A_MAX))
    assert v >= A_MAX**2 / J_MAX
    return v


def test_peak_motion_of_the_commands_matches_the_profile(bag: Any) -> None:
    run = read_run(bag("lin2k"))
    res = analyze(run)
    job = run.plan.job
    js = run.plan.joint_step
    layer_fork = job.turns_per_layer * job.fork_steps_per_rev
    layer_feed = round(job.turns_per_layer * job.wire_diameter / job.feed_step)
    index = job.pole_steps_per_rev // job.poles
    fork, feed, pole = res.axes["fork"], res.axes["feed"], res.axes["pole"]
    assert fork.cmd_v == pytest.approx(scurve_peak(layer_fork) * js[1], rel=1e-5)
    assert feed.cmd_v == pytest.approx(scurve_peak(layer_fork) * layer_feed / layer_fork * js[0], rel=1e-5)
    assert pole.cmd_v == pytest.approx(scurve_peak(index) * js[2], rel=1e-4)
    assert fork.cmd_a == pytest.approx(A_MAX * js[1], rel=1e-3)
    assert pole.cmd_a == pytest.approx(A_MAX * js[2], rel=1e-3)
    assert fork.cmd_j == pytest.approx(J_MAX * js[1], rel=0.02)
    # the simulated axes follow: same peak speed to within the step ripple
    assert fork.act_v == pytest.approx(fork.cmd_v, rel=0.01)
    assert res.steps_recorded == res.steps_total == run.plan.total_steps
    assert fork.steps_moved == job.poles * job.layers * layer_fork
    assert pole.steps_moved == (job.poles - 1) * index


def test_tracking_error_from_the_joint_topics(bag: Any) -> None:
    path = bag("lin2k")
    res = analyze(read_run(path))
    ref = rosbags_read(path)
    js = json.loads(ref["/winder/job"][0][1].data)["joint_step"]
    tc, cmd, _ = joint_arrays(ref["/winder/joint_commands"])
    ts, act, _ = joint_arrays(ref["/winder/joint_states"])
    np.testing.assert_array_equal(tc, ts)
    for i, axis in enumerate(("feed", "fork", "pole")):
        err = (cmd[:, i] - act[:, i]) / js[i]
        m = res.axes[axis]
        assert m.track_max_steps == pytest.approx(np.max(np.abs(err)), rel=1e-12)
        assert m.track_rms_steps == pytest.approx(np.sqrt(np.mean(err**2)), rel=1e-12)
        assert m.final_error_steps == pytest.approx(err[-1], rel=1e-9, abs=1e-9)
        assert m.net_slips == 0
    assert res.lost_steps == 0 and res.complete


def test_lost_steps(bag: Any) -> None:
    path = bag("slip")
    res = analyze(read_run(path))
    ref = rosbags_read(path)
    report = final_report(ref)
    cfg = json.loads(ref["/winder/sim_config"][0][1].data)
    js = json.loads(ref["/winder/job"][0][1].data)["joint_step"]
    _, cmd, _ = joint_arrays(ref["/winder/joint_commands"])
    _, act, _ = joint_arrays(ref["/winder/joint_states"])
    assert int(report["lost_steps"]) > 0
    assert res.lost_steps == int(report["lost_steps"])
    slips = 0
    for i, axis in enumerate(("feed", "fork", "pole")):
        a = cfg["axes"][axis]
        pitch = (2 * math.pi / a["Zr"]) / a["motor_step_angle"]  # commanded steps per tooth pitch
        final = (cmd[-1, i] - act[-1, i]) / js[i]
        assert res.axes[axis].net_slips == round(final / pitch)
        slips += abs(round(final / pitch))
    # every slip of a two-phase motor loses 4 full steps; none was undone here
    assert slips > 0 and 4 * slips == res.lost_steps
    r = run_cli("analyze", str(path), "--no-plots")
    assert r.returncode == 0, r.stderr
    assert f"lost steps (sim node)       {res.lost_steps}" in r.stdout


def test_three_profiles_in_one_table(bag: Any) -> None:
    paths = [bag("lin2k"), bag("trap"), bag("expo")]
    r = run_cli("analyze", *map(str, paths), "--json", "--no-plots")
    assert r.returncode == 0, r.stderr
    out = json.loads(r.stdout)
    assert [o["job_id"] for o in out] == ["lin2k", "trap", "expo"]
    assert [o["profile"] for o in out] == ["scurve", "trapezoid", "exponential"]
    assert out[2]["ramp"]["tau"] == TAU and out[1]["ramp"]["a_max"] == A_MAX
    js_fork = 2 * math.pi / 1024
    scurve, trap, expo = (o["axes"]["fork"] for o in out)
    # same job, same top speed
    for o in (scurve, trap, expo):
        assert o["cmd_v"] == pytest.approx(V_MAX * js_fork, rel=1e-5)
    assert trap["cmd_a"] == pytest.approx(A_MAX * js_fork, rel=1e-3)
    # the exponential ramp starts at W/tau, W = V/(1 - 1 %) its truncated asymptote
    w_tau = V_MAX / 0.99 / TAU * js_fork
    assert 0.95 * w_tau <= expo["cmd_a"] <= w_tau * 1.0001
    # the acceleration jumps of the trapezoid: jerk far beyond the S-curve's limit
    assert scurve["cmd_j"] == pytest.approx(J_MAX * js_fork, rel=0.02)
    assert trap["cmd_j"] > 10 * scurve["cmd_j"]
    assert all(o["command"]["mean"] == pytest.approx(2.5e-6, rel=2e-3) for o in out)
    table = run_cli("analyze", *map(str, paths), "--no-plots")
    assert table.returncode == 0, table.stderr
    head = table.stdout.splitlines()[0]
    assert all(p.name in head for p in paths)
    assert "exponential / linear" in table.stdout
    assert "v 2048, a 8192, j 65536" in table.stdout and "v 2048, tau 0.1" in table.stdout


@pytest.mark.parametrize("name", ["lin2k", "nlns", "trap", "slip"])
def test_the_live_summary_and_analyze_give_one_eq7(bag: Any, name: str) -> None:
    """The sim node's live figures (its final report, 7 significant digits) and
    winder analyze's are one function's (winder.contract.eq7): the mean and the
    maximum, of the commanded steps and of the axes, equal to the digits
    recorded, and the live summary's 3 decimals in um are analyze's."""
    path = bag(name)
    res = analyze(read_run(path))
    reports = [  # the sim node's job statuses, in any namespace, as rosbags decodes them
        {kv.key: kv.value for kv in st.values}
        for _, arr in rosbags_read(path)["/diagnostics"]
        for st in arr.status
        if st.name.endswith("sim_node: job")
    ]
    live = reports[-1]
    assert res.actual is not None
    for key, ours in (
        ("mean_deviation_actual_m", res.actual.mean),
        ("max_deviation_actual_m", res.actual.max),
        ("mean_deviation_command_m", res.command.mean),
        ("max_deviation_command_m", res.command.max),
    ):
        assert f"{ours:.6e}" == live[key], key  # the report's own format: every digit it holds
    table = run_cli("analyze", str(path), "--no-plots").stdout
    for key, row in (
        ("mean_deviation_actual_m", "eq.7 mean, axes"),
        ("mean_deviation_command_m", "eq.7 mean, command"),
    ):
        shown = next(ln for ln in table.splitlines() if ln.startswith(row))
        assert shown.split()[-2] == f"{float(live[key]) * 1e6:.3f}", shown  # as winder run prints it


def test_two_runs_side_by_side_mark_their_differences(bag: Any) -> None:
    """Set-up rows in which two runs differ are marked *, the others not;
    the motors are the ones the sim_config of each bag recorded."""
    lin, trap, nlns = bag("lin2k"), bag("trap"), bag("nlns")
    r = run_cli("analyze", str(lin), str(trap), "--no-plots")
    assert r.returncode == 0, r.stderr
    lines = r.stdout.splitlines()
    marked = {ln[2:].split("  ")[0] for ln in lines if ln.startswith("* ") and "  " in ln}
    # the job ids differ (lin2k, trap), the ramps and the joint-state rates; the motors do not
    assert marked == {"job", "profile / motor model", "ramp limits (major axis)", "joint-state rate"}, marked
    assert "* the runs differ in this setting" in lines
    r = run_cli("analyze", str(lin), str(nlns), "--no-plots")
    marked = {ln[2:].split("  ")[0] for ln in r.stdout.splitlines() if ln.startswith("* ") and "  " in ln}
    cfg = json.loads(rosbags_read(nlns)["/cell1/winder/sim_config"][0][1].data)
    assert cfg["axes"]["fork"]["J"] == 2e-4 and cfg["model"] == "nonlinear"
    assert {"fork: motor J, D", "feed: motor J, D", "pole: motor J, D", "profile / motor model"} <= marked
    assert "job" in marked  # another job id
    fork = next(ln for ln in r.stdout.splitlines() if "fork: motor J, D" in ln)
    assert "0.0002 kg m^2" in fork


def test_plots_are_written(bag: Any, tmp_path: Path) -> None:
    import matplotlib.image as mpimg

    r = run_cli("analyze", str(bag("trap")), "--plots-dir", str(tmp_path))
    assert r.returncode == 0, r.stderr
    for name in ("motion.png", "tracking.png", "winding.png"):
        f = tmp_path / name
        assert f"plot: {f}" in r.stdout
        assert f.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
        img = mpimg.imread(f)
        assert img.shape[0] >= 900 and img.shape[1] >= 1400
        assert np.std(img) > 0.05  # not a blank canvas
    ident = run_cli("identify", str(bag("trap")), "--plots-dir", str(tmp_path))
    assert ident.returncode == 0, ident.stderr
    assert (tmp_path / "identify.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_a_value_that_rounds_to_zero_prints_without_a_sign() -> None:
    """'-0.000 steps' appeared in the summary: a tiny negative is 0."""
    from winder.analysis.metrics import _f

    assert _f(-1e-9) == "0.000" and _f(-4e-4) == "0.000" and _f(-6e-4) == "-0.001"
    assert _f(2.5e-6, 1e6) == "2.500" and _f(float("nan")) == "-"


def test_export_csv_holds_every_message_and_step(bag: Any, tmp_path: Path) -> None:
    """winder export: each CSV file has one row per recorded message (per step
    for the step times), with the values rosbags decodes, and loads with numpy
    and the csv module; a damaged bag or an existing directory is refused."""
    import csv

    path = bag("lin2k")
    out = tmp_path / "csv"
    r = run_cli("export", str(path), "--csv", str(out))
    assert r.returncode == 0, r.stderr
    ref = rosbags_read(path)
    origin = json.loads(ref["/winder/sim_config"][0][1].data).get("clock_origin_ns", 0)
    for topic, name in (
        ("/winder/joint_states", "joint_states.csv"),
        ("/winder/joint_commands", "joint_commands.csv"),
    ):
        t, pos, vel = joint_arrays(ref[topic])
        table = np.loadtxt(out / name, delimiter=",", skiprows=1)
        assert table.shape == (len(ref[topic]), 7)
        np.testing.assert_allclose(table[:, 0], t - origin / 1e9, rtol=0, atol=1e-9)
        np.testing.assert_array_equal(table[:, 1:4], pos)
        np.testing.assert_array_equal(table[:, 4:7], vel)
        assert f"{out / name}  {len(ref[topic])} rows" in r.stdout
    steps = np.loadtxt(
        out / "step_times.csv", delimiter=",", skiprows=1, usecols=(0, 2, 3, 4, 5), dtype=np.int64
    )
    np.testing.assert_array_equal(steps, step_rows(ref["/winder/step_times"]))
    with open(out / "step_times.csv", newline="") as f:
        head = next(csv.reader(f))
    assert head == ["t_ns", "t_s", "segment", "feed_steps", "fork_steps", "pole_steps"]
    meta = json.loads((out / "run.json").read_text())
    assert meta["rows"]["step_times.csv"] == steps.shape[0] and meta["final_report"]["state"] == "done"
    again = run_cli("export", str(path), "--csv", str(out))
    assert again.returncode == 2 and "already exists" in again.stderr and "Traceback" not in again.stderr
    damaged = tmp_path / "damaged"
    shutil.copytree(path, damaged)
    mcap = next(damaged.glob("*.mcap"))
    data = bytearray(mcap.read_bytes())
    data[len(data) // 2] ^= 0x10  # inside a chunk of the uncompressed bag's data section
    mcap.write_bytes(bytes(data))
    refused = run_cli("export", str(damaged), "--csv", str(tmp_path / "d"))
    assert refused.returncode == 2 and "Traceback" not in refused.stderr, refused.stderr
    assert not (tmp_path / "d").exists() and not list(tmp_path.glob(".d.*"))
