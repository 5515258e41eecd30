"""The wire in a simulated run: `winder run` on a rectangular core, its bag
read back. The recorded tension is recomputed here from the recorded
flyer (its simulated angle and speed in winder/joint_states) through the
layer's contour and scipy's lsim of the tensioner; the supply and dancer
joints are in the joint states; a wire pulled past its breaking load stops
the run, said in one line."""

from __future__ import annotations

import json
import subprocess
from pathlib import Path

import numpy as np
import pytest
import scipy.signal
from conftest import Procs, rosbags_read
from support import wait
from support.bags import job_doc
from support.cell import only_bag, servo_rect_job, winder_run
from support.paths import BIN

from winder.motion.job import Job
from winder.record.reader import read_run
from winder.tension.tensioner import tensioner_of

pytestmark = pytest.mark.ros

RECT = [
    "--job-id", "rect", "--wire-diameter", "0.0005", "--wire.bare-diameter", "0.00045",
    "--bobbin.core", "rect", "--bobbin.core-width", "0.012", "--bobbin.core-depth", "0.02",
    "--bobbin.core-corner-radius", "0.001", "--flyer-radius", "0.03", "--turns-per-layer", "6",
    "--layers", "2", "--poles", "1", "--fork-steps-per-rev", "512", "--feed-step", "1e-5",
]  # fmt: skip


def test_the_recorded_tension_is_the_recorded_flyers(tmp_path: Path, procs: Procs) -> None:
    r = winder_run(tmp_path, procs.domain, *RECT, "--publish-rate", "2000", "--v-max", "1500")
    assert r.returncode == 0, r.stdout + r.stderr
    bag = rosbags_read(only_bag(tmp_path))
    states = bag["/winder/joint_states"]
    names = list(states[0][1].name)
    assert names == ["feed", "fork", "pole", "supply", "dancer"]
    t = np.array([m.header.stamp.sec + m.header.stamp.nanosec * 1e-9 for _, m in states])
    pos = np.array([m.position for _, m in states])
    vel = np.array([m.velocity for _, m in states])
    wrench = bag["/winder/tension"]
    assert [m.header.stamp for _, m in wrench] == [m.header.stamp for _, m in states]  # one a sample
    tension = np.array([m.wrench.force.x for _, m in wrench])
    config = json.loads(bag["/winder/sim_config"][0][1].data)["wire"]
    assert config["tensioner"] == "dancer"

    # the take-up, worked out here from the recorded flyer: the layer is the one the feed is on
    job = Job.from_dict(job_doc(bag["/winder/job"][0][1])["job"])
    plan_layers = [seg for seg in job.segments() if seg.kind.winds]
    fork_per_layer = [(seg.start[1], seg.start[1] + seg.delta[1]) for seg in plan_layers]
    assert len(plan_layers) == 2
    steps = pos[:, 1] / (2 * np.pi / job.fork_steps_per_rev)
    first_end = fork_per_layer[0][1]
    which = np.where(steps <= first_end, 0, 1)
    radii = [job.winding.coils[0].layers[i].radius for i in range(2)]
    contours = [job.bobbin.contour(r) for r in radii]
    v = np.zeros(t.size)
    for i, contour in enumerate(contours):
        on = which == i
        v[on] = np.abs(vel[on, 1]) * contour.lever(pos[on, 1], job.flyer_radius)
    tensioner = tensioner_of({}, job.wire.stiffness_per_length, job.set_tension)
    a, b, c, d = tensioner.matrices()
    _, y, x = scipy.signal.lsim((a, b[:, None], c, d[:, None]), v, t - t[0])
    # the layer change is a moment of the flyer's: the samples around it may be on either layer
    ok = np.abs(steps - first_end) >= 2
    want = np.maximum(job.set_tension + y[:, 0], 0)
    assert np.allclose(tension[ok], want[ok], rtol=0, atol=2e-3 * job.set_tension)
    assert np.allclose(pos[ok, 4], y[ok, 1], rtol=0, atol=1e-5)  # the dancer's travel
    # the supply paid out what the coil took, less what the dancer's loop and the span hold
    taken = np.concatenate([[0.0], np.cumsum((v[1:] + v[:-1]) / 2 * np.diff(t))])
    held = x[:, 0] + 2 * x[:, 1]
    assert np.allclose(pos[:, 3], taken - held, rtol=0, atol=1e-3 * taken[-1])
    report = {kv.key: kv.value for kv in bag["/diagnostics"][-1][1].status[0].values}
    assert float(report["tension_peak_n"]) >= float(report["tension_min_n"]) > 0
    # within the bands all through: said so, and in winder run's summary
    assert report["tension_outside_alarm_s"] == report["tension_outside_warning_s"] == "0.000"
    span = f"{report['tension_min_n']}..{report['tension_peak_n']} N"
    assert f"  wire tension       {span}\n" in r.stdout, r.stdout
    band = (tension < job.set_tension * 0.8) | (tension > job.set_tension * 1.2)
    assert not band.any()
    # winder's reader takes the same tension (its fast path against rosbags' decoder), and
    # winder analyze draws it
    run = read_run(only_bag(tmp_path))
    assert np.array_equal(run.tension.tension, tension)
    from winder.analysis.metrics import analyze

    wire = analyze(run).wire
    assert (wire["tension_min_n"], wire["tension_peak_n"]) == (tension.min(), tension.max())
    assert wire["outside_alarm_s"] == wire["outside_warning_s"] == 0.0
    assert np.allclose(run.tension.t, t - t[0], rtol=0, atol=1e-9)
    out = subprocess.run(
        [str(BIN / "winder"), "analyze", str(only_bag(tmp_path)), "--plots-dir", str(tmp_path / "plots")],
        capture_output=True,
        text=True,
        timeout=180,
    )
    assert out.returncode == 0, out.stderr
    assert (tmp_path / "plots" / "wire.png").stat().st_size > 10_000


BREAKS = servo_rect_job("breaks", layers=1, v_max=60000.0, bandwidth=2.0)


def test_a_wire_pulled_past_its_breaking_load_stops_the_run(tmp_path: Path, procs: Procs) -> None:
    """A job `winder run` refuses (its predicted tension), started on the nodes
    themselves with the sim node's wire check off: its wire breaks, the run
    stops incomplete, a `wire` ERROR names where."""
    job = tmp_path / "breaks.yaml"
    job.write_text(BREAKS)
    refused = winder_run(tmp_path, procs.domain, str(job))
    assert refused.returncode == 2 and "passes the wire's maximum" in refused.stderr, refused.stderr
    bags = tmp_path / "nodes"
    # wire_check off: the sim node winds it anyway, and its wire shows what happens
    procs.start("sim_node", "--params-file", str(job), "-p", f"bag_dir:={bags}", "-p", "wire_check:=false")
    procs.start("profile_node", "--params-file", str(job))
    procs.start("interp_node", "--params-file", str(job))
    done = ("incomplete", "done", "aborted")
    wait.until(
        lambda: (
            (metas := list(bags.glob("*/metadata.yaml")))
            and read_run(metas[0].parent).report.get("state") in done
        ),
        60,
        f"a bag in {bags} with its run's final report",
        poll=0.2,
    )
    [meta] = list(bags.glob("*/metadata.yaml"))
    run = read_run(meta.parent)
    assert run.report["state"] == "incomplete", run.report
    assert any(
        ": wire: wire break at coil 1 layer 1 turn " in e and "its breaking load 34.99 N, 220 MPa" in e
        for e in run.errors
    ), run.errors
    said = next(e for e in run.errors if "pulled to its breaking load: " in e)  # the wire, then the job
    pulled = float(said.split("pulled to its breaking load: ")[1].split(" N")[0])
    assert pulled > 34.99  # the tension it parted at; from that sample on it holds none
    assert float(run.report["tension_peak_n"]) < pulled


@pytest.mark.parametrize(
    ("fault", "words", "turn"),
    [
        (["--fault.wire-break-turn", "8"], "wire break at coil 1 layer 2 turn 8 (", 8),
        (["--fault.slip-turn", "3"], "wire slip at coil 1 layer 1 turn 3 (", 3),
    ],
)
def test_an_injected_fault_is_caught_at_its_turn(
    tmp_path: Path, procs: Procs, fault: list[str], words: str, turn: int
) -> None:
    """A break and a slip injected at a turn of the job: caught in that turn
    (the recorded flyer's angle at the fault's time says which), the run
    stopped there incomplete, `winder run` exits 1 naming it, and the bag
    reads to its end."""
    r = winder_run(tmp_path, procs.domain, *RECT, "--publish-rate", "2000", "--v-max", "1500", *fault)
    assert r.returncode == 1, r.stdout + r.stderr
    last = r.stderr.strip().splitlines()[-1]
    assert last.startswith("winder run: job rect: incomplete, ") and words in last, r.stderr
    bag = rosbags_read(only_bag(tmp_path))  # every message, to the end
    statuses = [st for _, m in bag["/diagnostics"] for st in m.status if st.name.endswith(": wire")]
    assert len(statuses) == 1 and statuses[0].message.startswith(words.rstrip(" ("))
    values = {kv.key: kv.value for kv in statuses[0].values}
    kind = "break" if "break" in words else "slip"
    assert (values["fault"], values["coil"], values["layer"], values["turn"]) == (
        kind,
        "1",
        str(1 + (turn > 6)),
        str(turn),
    )
    states = bag["/winder/joint_states"]
    t = np.array([m.header.stamp.sec + m.header.stamp.nanosec * 1e-9 for _, m in states])
    t -= t[0]
    fork = np.array([m.position[1] for _, m in states])
    at = int(np.searchsorted(t, float(values["t_s"]) - 1e-9))
    assert turn - 1 <= fork[at] / (2 * np.pi) < turn  # the job's turn (one coil: the coil's)
    tension = np.array([m.wrench.force.x for _, m in bag["/winder/tension"]])
    if kind == "break":  # the wire held up to there, and nothing from there on
        assert tension[at - 1] > 1.0 and not tension[at:].any()
    assert t[-1] - t[at] <= 0.02  # the axes stopped as the watch saw it (10 ms on, for a break)
    run = read_run(only_bag(tmp_path))
    assert run.report["state"] == "incomplete" and int(run.report["steps_done"]) < int(
        run.report["steps_total"]
    )


CORES = {
    "rect": ["--bobbin.core", "rect", "--bobbin.core-width", "0.012", "--bobbin.core-depth", "0.02"],
    "square": ["--bobbin.core", "rect", "--bobbin.core-width", "0.016", "--bobbin.core-depth", "0.016"],
    "round": ["--bobbin.core", "round", "--bobbin.core-diameter", "0.016"],
}


def turn_harmonics(tmp_path: Path, domain: int, core: str, v_max: int) -> np.ndarray:
    """The recorded tension's harmonics of the flyer's turn (N; index m: m
    times a turn) over the last 8 turns the flyer cruised, resampled evenly
    in its recorded angle: numpy's FFT of the bag, nothing of winder's."""
    out = tmp_path / f"{core}_{v_max}"
    out.mkdir()
    args = [
        *["--job-id", "ripple", "--wire-diameter", "0.0005", "--wire.bare-diameter", "0.00045"],
        *["--flyer-radius", "0.03", "--turns-per-layer", "16", "--layers", "1", "--poles", "1"],
        *["--fork-steps-per-rev", "512", "--feed-step", "1e-5", "--publish-rate", "2000"],
        *(["--bobbin.core-corner-radius", "0.001"] if core != "round" else []),
    ]
    r = winder_run(out, domain, *args, *CORES[core], "--v-max", str(v_max))
    assert r.returncode == 0, r.stdout + r.stderr
    bag = rosbags_read(only_bag(out))
    psi = np.array([m.position[1] for _, m in bag["/winder/joint_states"]])
    omega = np.array([m.velocity[1] for _, m in bag["/winder/joint_states"]])
    tension = np.array([m.wrench.force.x for _, m in bag["/winder/tension"]])
    cruise = np.flatnonzero(np.abs(omega - omega.max()) < 1e-3 * omega.max())
    a, b = cruise[0], cruise[-1]
    assert psi[b] - psi[a] > 10 * 2 * np.pi  # cruising over 10 turns and more
    if core == "round":  # the wire paid out is what the 16 turns took, the dancer's loop aside
        last = bag["/winder/joint_states"][-1][1]
        took = 16 * 2 * np.pi * (0.016 / 2 + 0.0005 / 2)
        assert abs(last.position[3] + 2 * last.position[4] - took) < 1e-3 * took
    turns = 8
    grid = np.linspace(psi[b] - turns * 2 * np.pi, psi[b], turns * 256, endpoint=False)
    y = np.interp(grid, psi[a : b + 1], tension[a : b + 1])
    spectrum = np.abs(np.fft.rfft(y - y.mean())) * 2 / y.size
    return spectrum[: 9 * turns : turns]  # m = 0..8


def test_the_ripple_follows_the_cores_corners(tmp_path: Path, procs: Procs) -> None:
    """While the flyer cruises: a rectangle's tension ripples at twice the
    turn rate (its even harmonics only), a square's at four times, a round
    core's not at all; faster, the ripple is larger. On the round core the
    supply paid out what the turns took (2 pi r a turn)."""
    rect = turn_harmonics(tmp_path, procs.domain, "rect", 3000)
    assert rect[2] > 100 * max(rect[1], rect[3], rect[5]) and rect[4] > 100 * rect[3]
    square = turn_harmonics(tmp_path, procs.domain, "square", 3000)
    assert square[4] > 100 * max(square[1], square[2], square[3], square[5], square[6])
    round_ = turn_harmonics(tmp_path, procs.domain, "round", 3000)
    assert round_[1:].max() < 0.01 * rect[2]
    slower = turn_harmonics(tmp_path, procs.domain, "rect", 1500)
    assert rect[2] > 1.5 * slower[2]


def test_the_sim_node_refuses_a_job_whose_wire_would_not_hold(tmp_path: Path, procs: Procs) -> None:
    """The same job started on the nodes themselves, the sim node's wire
    check on (its default): the run stops as it starts, before a step runs,
    in `winder check`'s words."""
    job = tmp_path / "breaks.yaml"
    job.write_text(BREAKS)
    check = subprocess.run(
        [str(BIN / "winder"), "check", str(job)], capture_output=True, text=True, timeout=60
    )
    assert check.returncode == 2, check.stdout + check.stderr
    words = check.stderr.strip().removeprefix("winder check: error: ")
    bags = tmp_path / "nodes"
    procs.start("sim_node", "--params-file", str(job), "-p", f"bag_dir:={bags}")
    procs.start("profile_node", "--params-file", str(job))
    procs.start("interp_node", "--params-file", str(job))
    wait.until(
        lambda: (
            (metas := list(bags.glob("*/metadata.yaml")))
            and read_run(metas[0].parent).report.get("state") in ("incomplete", "done", "aborted")
        ),
        60,
        f"a bag in {bags} with its run's final report",
        poll=0.2,
    )
    [meta] = list(bags.glob("*/metadata.yaml"))
    run = read_run(meta.parent)
    assert run.report["state"] == "incomplete" and int(run.report["steps_done"]) == 0, run.report
    assert any(e.endswith(f": wire: job breaks refused: {words}") for e in run.errors), (words, run.errors)
