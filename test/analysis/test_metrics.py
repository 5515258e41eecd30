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
from conftest import final_report, is_consumer, rosbags_read
from mcap.reader import make_reader
from support.bags import control_docs, job_doc, joint_arrays, step_rows
from support.cli import assert_one_line_error, run_cli

from winder.analysis.metrics import analyze, step_kinematics
from winder.record.reader import read_run

pytestmark = pytest.mark.ros

V_MAX, A_MAX, J_MAX, TAU = (
    2048.0,
    8192.0,
    65536.0,
    0.1,
)  # the profile node's defaults (steps of the major axis)


def eq7_by_hand(path: Path) -> tuple[float, float, list[float]]:
    """Mean and max distance of every commanded step of every layer to its line
    (eq. 5 and 7 of the 2016 paper), and the mean per turn, from the raw bag."""
    ref = rosbags_read(path)
    ns = next(k for k in ref if k.endswith("/winder/job"))[: -len("/winder/job")]
    job = job_doc(ref[f"{ns}/winder/job"][0][1])
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
        # the claim of docs/THEORY.md: minimum deviation = a quarter of the 10 um feed step, 0.1 % of the wire
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
    job = job_doc(ref["/winder/job"][0][1])
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
    js = job_doc(ref["/winder/job"][0][1])["joint_step"]
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
    js = job_doc(ref["/winder/job"][0][1])["joint_step"]
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


@pytest.mark.parametrize("name", ["lin2k", "nlns", "trap", "slip", "abort"])
def test_the_live_summary_and_analyze_give_one_eq7(bag: Any, name: str) -> None:
    """The sim node's live figures (its final report, 7 significant digits) and
    winder analyze's are one function's (winder.contract.eq7): the mean and the
    maximum, of the commanded steps and of the axes, equal to the digits
    recorded, and the live summary's 3 decimals in um are analyze's."""
    path = bag(name)
    res = analyze(read_run(path))
    reports = [  # the sim node's job statuses, in any namespace, as rosbags decodes them
        values
        for _, arr in rosbags_read(path)["/diagnostics"]
        for st in arr.status
        if is_consumer(st.name, values := {kv.key: kv.value for kv in st.values}, None)
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


def _marked(table: str) -> dict[str, bool]:
    """The table's row names, each with whether it is marked ``*``."""
    rows = table.splitlines()[2:]
    return {ln[2:].split("  ")[0]: ln.startswith("* ") for ln in rows if ln[:2] in ("* ", "  ")}


def _recorded_setup(path: Path) -> dict[str, Any]:
    """What a bag says it ran with, as rosbags decodes it: job, ramp, motors, rate, compression."""
    ref = rosbags_read(path)
    ns = next(k for k in ref if k.endswith("/winder/job"))[: -len("/winder/job")]
    job = job_doc(ref[f"{ns}/winder/job"][0][1])
    cfg = json.loads(ref[f"{ns}/winder/sim_config"][0][1].data)
    ramp = json.loads(ref[f"{ns}/winder/profile_config"][-1][1].data)
    with next(path.glob("*.mcap")).open("rb") as f:  # the chunk compression, by the mcap library
        summary = make_reader(f).get_summary()
    assert summary is not None
    out: dict[str, Any] = {
        "bag compression": {c.compression or "none" for c in summary.chunk_indexes},
        "job id": job["job"]["job_id"],
        "job": {k: job["job"][k] for k in ("poles", "layers", "turns_per_layer", "wire_diameter")},
        "profile / motor model": (ramp["profile"], cfg["model"]),
        "joint-state rate": cfg["publish_rate"],
    }
    for axis, m in cfg["axes"].items():
        out[f"{axis}: motor J, D"] = (m["J"], m["D"], m["load_torque"])
        out[f"{axis}: motor Zr, L, i_a"] = (m["Zr"], m["L"], m["i_a"], m["motor_step_angle"])
    return out


def test_two_runs_side_by_side_mark_their_differences(bag: Any) -> None:
    """Set-up rows in which two runs differ are marked *, the others not: the
    expectation is worked out from what each bag recorded (its job, ramp and
    sim_config, as rosbags decodes them), per row."""
    lin, trap, nlns = bag("lin2k"), bag("trap"), bag("nlns")
    for a, b in ((lin, trap), (lin, nlns)):
        r = run_cli("analyze", str(a), str(b), "--no-plots")
        assert r.returncode == 0, r.stderr
        marked = _marked(r.stdout)
        sa, sb = _recorded_setup(a), _recorded_setup(b)
        for row in sa:
            assert marked[row] == (sa[row] != sb[row]), (row, sa[row], sb[row])
        assert "* the runs differ in this setting" in r.stdout.splitlines()
        # the rows of the results are never marked
        assert not any(marked[n] for n in ("run", "state", "steps", "eq.7 mean, axes", "fork: steps moved"))
    # lin2k is recorded uncompressed, trap and nlns with lz4 chunks (the default)
    assert marked["bag compression"]
    r = run_cli("analyze", str(lin), str(nlns), "--no-plots", "--json")
    out = json.loads(r.stdout)
    assert out[0]["setup_differs"] == out[1]["setup_differs"]
    assert {"model", "fork.J", "feed.D", "pole.J", "compression"} <= set(out[0]["setup_differs"])
    assert not {"fork.D", "feed.J", "pole.D", "fork.Zr"} & set(out[0]["setup_differs"])
    assert [o["compression"] for o in out] == ["none", "lz4"]
    fork = next(
        ln
        for ln in run_cli("analyze", str(nlns), "--no-plots").stdout.splitlines()
        if "fork: motor J, D" in ln
    )
    assert "0.0002 kg m^2" in fork
    # one bag: nothing is marked
    assert not any(_marked(run_cli("analyze", str(lin), "--no-plots").stdout).values())


def test_runs_whose_rows_differ_side_by_side(bag: Any, tmp_path: Path) -> None:
    """A run without joint samples (its "as wound" is one row, not three)
    beside one with them: the table has every row of either run, in order,
    and "-" in a run's column where it has none (it died with an IndexError
    when ``winder analyze bags/rw400_*`` met such a pair: fresh-clone CI)."""
    from winder.record.bag import BagRecorder
    from winder.record.raw import read_raw

    lin = bag("lin2k")
    raw = read_raw(lin)
    topics = {c.topic: c.msgtype for c in raw.connections.values() if c.topic != "/winder/joint_states"}
    rec = BagRecorder(tmp_path / "no_joints", topics, compression="none")
    for cid, t, data in raw.messages:
        if raw.connections[cid].topic in topics:
            rec.write(raw.connections[cid].topic, t, data, exact=True)
    rec.close()
    r = run_cli("analyze", str(lin), str(tmp_path / "no_joints"), "--no-plots")
    assert r.returncode == 0, r.stderr
    rows = {ln[2:].split("  ")[0].strip(): ln for ln in r.stdout.splitlines() if ln[:2] in ("* ", "  ")}
    assert "as wound" in rows and "as wound: turns laid" in rows, r.stdout
    # the run with samples has no plain "as wound" row, the other none of the three
    assert rows["as wound"].split()[-1] == "samples)" and " - " in rows["as wound"], rows["as wound"]
    assert rows["as wound: turns laid"].rstrip().endswith("-"), rows["as wound: turns laid"]


def test_an_aborted_run_counts_the_steps_it_simulated(bag: Any) -> None:
    """An aborted job: the steps simulated, from the sim node's final report,
    equal the step rows the bag holds up to the abort's rest and the last
    commanded position; the table and the JSON say so, and of how many."""
    path = bag("abort")
    ref = rosbags_read(path)
    report = final_report(ref)
    job = job_doc(ref["/winder/job"][0][1])
    total = sum(s["steps"] for s in job["segments"])
    rows = step_rows(ref["/winder/step_times"])
    (abort,) = [e for e in control_docs(ref["/winder/control"]) if e["event"] == "abort"]
    simulated = int(report["steps_done"])
    assert report["state"] == "aborted" and 0 < simulated < total
    assert simulated == int(np.sum(rows[:, 0] <= abort["t_rest_ns"])) == abort["steps"]
    # the axes were commanded to the position of the last simulated step, and stayed there
    _, cmd, _ = joint_arrays(ref["/winder/joint_commands"])
    js = np.asarray(job["joint_step"])
    np.testing.assert_allclose(cmd[-1] / js, rows[simulated - 1, 2:], atol=1e-6)
    r = run_cli("analyze", str(path), "--no-plots")
    assert r.returncode == 0, r.stderr
    steps = next(ln for ln in r.stdout.splitlines() if ln.startswith("steps "))
    assert steps.split("  ")[-1].strip() == (
        f"{simulated} simulated, {rows.shape[0]} recorded, of {total} (aborted at rest)"
    ), steps
    assert str(total) + " simulated" not in r.stdout
    out = json.loads(run_cli("analyze", str(path), "--no-plots", "--json").stdout)[0]
    assert (out["steps_simulated"], out["steps_recorded"], out["steps_total"]) == (
        simulated,
        rows.shape[0],
        total,
    )
    assert out["state"] == "aborted" and out["stream"]["steps_missing"] == 0


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
    from winder.analysis.metrics import _f, _g

    assert _f(-1e-9) == "0.000" and _f(-4e-4) == "0.000" and _f(-6e-4) == "-0.001"
    assert _f(2.5e-6, 1e6) == "2.500" and _f(float("nan")) == "-"
    assert _g(-0.0) == "0" and _g(-0.0, 1e6) == "0" and _g(-2.5e-3) == "-0.0025"


@pytest.mark.parametrize("name", ["lin2k", "nlns", "abort"])
def test_export_csv_holds_every_message_and_step(bag: Any, tmp_path: Path, name: str) -> None:
    """winder export: each CSV file has one row per recorded message (per step
    for the step times, per operator event), with the values rosbags decodes,
    headers that name the unit and are identifiers MATLAB's readtable keeps,
    no "-0"; it loads with numpy and the csv module. Uncompressed (lin2k), lz4
    in a namespace (nlns), an aborted run with its event (abort)."""
    import csv
    import re

    path = bag(name)
    out = tmp_path / "csv"
    r = run_cli("export", str(path), "--csv", str(out))
    assert r.returncode == 0, r.stderr
    ref = rosbags_read(path)
    ns = next(k for k in ref if k.endswith("/winder/job"))[: -len("/winder/job")]
    origin = json.loads(ref[f"{ns}/winder/sim_config"][0][1].data).get("clock_origin_ns", 0)
    for topic, file in (
        (f"{ns}/winder/joint_states", "joint_states.csv"),
        (f"{ns}/winder/joint_commands", "joint_commands.csv"),
    ):
        t, pos, vel = joint_arrays(ref[topic])
        table = np.loadtxt(out / file, delimiter=",", skiprows=1)
        assert table.shape == (len(ref[topic]), 7)
        np.testing.assert_allclose(table[:, 0], t - origin / 1e9, rtol=0, atol=1e-9)
        np.testing.assert_array_equal(table[:, 1:4], pos)
        np.testing.assert_array_equal(table[:, 4:7], vel)
        assert f"{out / file}  {len(ref[topic])} rows" in r.stdout
    rows = step_rows(ref[f"{ns}/winder/step_times"])
    steps = np.loadtxt(out / "step_times.csv", delimiter=",", skiprows=1, ndmin=2)
    np.testing.assert_array_equal(steps[:, [0, 2, 3, 4, 5]].astype(np.int64), rows)
    np.testing.assert_allclose(steps[:, 1], rows[:, 0] / 1e9, rtol=0, atol=1e-12)
    events = control_docs(ref.get(f"{ns}/winder/control", []))
    with open(out / "events.csv", newline="") as f:
        listed = list(csv.DictReader(f))
    assert [(e["event"], float(e["t_s"])) for e in listed] == [
        (e["event"], pytest.approx(e["t_ns"] / 1e9, abs=1e-9)) for e in events
    ]
    assert (name == "abort") == any(e["event"] == "abort" for e in listed)
    for file in ("joint_states.csv", "joint_commands.csv", "step_times.csv", "events.csv", "errors.csv"):
        text = (out / file).read_text()
        head = text.split("\n", 1)[0].split(",")
        assert all(re.fullmatch(r"[A-Za-z][A-Za-z0-9_]*", h) for h in head), head
        assert not re.search(r"(^|,)-0(\.0*)?(,|$)", text, flags=re.M), file
    meta = json.loads((out / "run.json").read_text())
    assert meta["rows"]["step_times.csv"] == rows.shape[0] and meta["final_report"] == final_report_of(
        ref, ns
    )
    assert meta["compression"] == ("none" if name == "lin2k" else "lz4")
    assert sorted(p.name for p in out.iterdir()) == sorted([*meta["rows"], "run.json"])
    assert not list(tmp_path.glob(".csv.*"))  # the temporary directory was renamed


def final_report_of(ref: dict[str, list[tuple[int, Any]]], ns: str) -> dict[str, str]:
    """The last job status of the step consumer of the cell in ``ns``."""
    return final_report(ref, ns)


def test_export_refuses_what_it_cannot_write_whole(bag: Any, tmp_path: Path) -> None:
    """An existing directory, a damaged bag and a cut-short one are refused
    with one line and status 2, and nothing is left behind."""
    path = bag("lin2k")
    out = tmp_path / "csv"
    out.mkdir()
    assert_one_line_error(run_cli("export", str(path), "--csv", str(out)), "already exists")
    assert list(out.iterdir()) == []
    damaged = tmp_path / "damaged"
    shutil.copytree(path, damaged)
    mcap = next(damaged.glob("*.mcap"))
    data = bytearray(mcap.read_bytes())
    data[len(data) // 2] ^= 0x10  # inside a chunk of the uncompressed bag's data section
    mcap.write_bytes(bytes(data))
    assert_one_line_error(
        run_cli("export", str(damaged), "--csv", str(tmp_path / "d")),
        "damaged recording",
        "nothing is written",
    )
    cut = tmp_path / "cut"
    cut.mkdir()
    (cut / mcap.name).write_bytes(bytes(data[: len(data) // 3]))  # no footer, no metadata.yaml
    assert_one_line_error(
        run_cli("export", str(cut), "--csv", str(tmp_path / "c")), "cut short", "bag recover"
    )
    assert sorted(p.name for p in tmp_path.iterdir()) == ["csv", "cut", "damaged"]
