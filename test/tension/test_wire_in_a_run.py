"""The wire in a simulated run: `winder run` on a rectangular core, its bag
read back. The recorded tension is recomputed here from the recorded
flyer (its simulated angle and speed in winder/joint_states) through the
layer's contour and scipy's lsim of the tensioner; the supply and dancer
joints are in the joint states; a wire pulled past its breaking load stops
the run, said in one line."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
import scipy.signal
from conftest import Procs, rosbags_read
from support.cell import only_bag, winder_run

from winder.motion.job import Job
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
    job = Job.from_dict(json.loads(bag["/winder/job"][0][1].data)["job"])
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


def test_a_wire_pulled_past_its_breaking_load_stops_the_run(tmp_path: Path, procs: Procs) -> None:
    job = tmp_path / "servo.yaml"
    job.write_text("sim_node:\n  ros__parameters:\n    tensioner.kind: servo\n    tensioner.bandwidth: 2.0\n")
    r = winder_run(tmp_path, procs.domain, str(job), *RECT, "--layers", "1", "--v-max", "60000")
    assert r.returncode == 1, r.stdout + r.stderr
    assert "Traceback" not in r.stdout + r.stderr
    assert "the wire broke " in r.stdout + r.stderr, r.stdout + r.stderr
    assert "its breaking load 34.99 N, 220 MPa" in r.stdout + r.stderr
    bag = rosbags_read(only_bag(tmp_path))
    statuses = [s for _, m in bag["/diagnostics"] for s in m.status]
    final = {kv.key: kv.value for kv in statuses[-1].values}
    assert final["state"] == "incomplete"
    wire = [s for s in statuses if s.name.endswith(": wire")]
    assert wire and wire[0].level == 2 and wire[0].message.startswith("the wire broke "), wire
