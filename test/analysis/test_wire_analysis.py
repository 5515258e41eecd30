"""The wire in ``winder analyze`` (winder.analysis.wire, the ``wire`` object of
--json, its rows, wire.png and the stretched and slack turns of the coil as
wound), on runs the real nodes recorded: the session's ``wire`` run (a dancer
holding the set tension) and two runs of the nodes started on a job ``winder
run`` refuses: a servo that lets the tension swing past the wire's yield and
below the alarm band, and a slower one whose wire breaks (the tension drops
to nothing: the sim node's watch stops the run).

Every expected value is worked out here from the bag as rosbags reads it:
the layer of each sample by a loop over the step rows and the fork's ranges,
the stress from the tension, the bare section and the whirl at the take-up
speed of the recorded flyer, the stretch and the resistance from their
formulas, the turns from the flyer's recorded angle."""

from __future__ import annotations

import itertools
import json
import math
import subprocess
from collections.abc import Iterator
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from conftest import BIN, Procs, next_domain, release_domain, rosbags_read
from hypothesis import given
from hypothesis import strategies as st
from rosbags.rosbag2 import StoragePlugin
from support import wait
from support.bags import job_doc, step_rows, write_bag
from support.cell import servo_rect_job

from winder.analysis.metrics import analyze, format_table
from winder.analysis.wire import stresses
from winder.analysis.wound import as_wound
from winder.motion.job import Job
from winder.record.msgtypes import jazzy_store
from winder.record.reader import read_run

#: a servo too slow for the corners: past the yield and below the alarm band in
#: turns, never broken; and a slower one: the tension drops to nothing, the wire
#: breaks (the sim node's watch) in the second layer
RUNS = {
    "swings": {"bandwidth": 90.0},
    "breaks": {"bandwidth": 60.0},
}


@pytest.fixture(scope="module")
def runs(tmp_path_factory: pytest.TempPathFactory) -> Iterator[dict[str, Path]]:
    """The bag of each of RUNS, its nodes started side by side on domains of their own."""
    root = tmp_path_factory.mktemp("wire_runs")
    cells: dict[str, Procs] = {}
    try:
        for name, values in RUNS.items():
            params = root / f"{name}.yaml"
            params.write_text(
                servo_rect_job(
                    name,
                    layers=3,
                    v_max=15000.0,
                    bandwidth=values["bandwidth"],
                    extra="    tension.set: 9.0\n",
                )
            )
            (root / name).mkdir()
            cells[name] = procs = Procs(next_domain(), root / name)
            procs.start(
                "sim_node",
                "--params-file",
                str(params),
                "-p",
                f"bag_dir:={root / name / 'bags'}",
                "-p",
                "wire_check:=false",  # wound anyway: its wire stretches and breaks
            )
            procs.start("profile_node", "--params-file", str(params))
            procs.start("interp_node", "--params-file", str(params))
        bags = {name: _finished(root / name / "bags") for name in RUNS}
    finally:
        for procs in cells.values():
            procs.stop_all()
            release_domain(procs.domain)
    yield bags


def _finished(bags: Path) -> Path:
    def done() -> bool:
        metas = list(bags.glob("*/metadata.yaml"))
        return bool(metas) and read_run(metas[0].parent).report.get("state") in ("done", "incomplete")

    wait.until(done, 90, f"a bag in {bags} with its run's final report", poll=0.2)
    [meta] = list(bags.glob("*/metadata.yaml"))
    return meta.parent


# -- the oracle: from the bag as rosbags reads it --------------------------------------------


class Recorded:
    """A bag read by rosbags: the job, the tension and joint samples (their
    times from the run's start), the step rows, the diagnostics."""

    def __init__(self, path: Path) -> None:
        ref = rosbags_read(path)
        doc = job_doc(ref["/winder/job"][0][1])
        self.job = Job.from_dict(doc["job"])
        self.segments = doc["segments"]
        self.joint_step = doc["joint_step"]
        origin = json.loads(ref["/winder/sim_config"][0][1].data).get("clock_origin_ns", 0)

        def stamp(m: Any) -> int:
            return int(m.header.stamp.sec) * 10**9 + int(m.header.stamp.nanosec) - origin

        states = [m for _, m in ref["/winder/joint_states"]]
        self.names = list(states[0].name)
        self.t_ns = np.array([stamp(m) for m in states])
        self.pos = np.array([m.position for m in states])
        self.vel = np.array([m.velocity for m in states])
        wrench = [m for _, m in ref["/winder/tension"]]
        assert [stamp(m) for m in wrench] == self.t_ns.tolist()  # one tension sample a joint sample
        self.tension = np.array([m.wrench.force.x for m in wrench])
        self.rows = step_rows(ref["/winder/step_times"])
        self.diagnostics = ref["/diagnostics"]

    def fork(self) -> tuple[np.ndarray, np.ndarray]:
        i = self.names.index("fork")
        return self.pos[:, i], self.vel[:, i]

    def layer_of_samples(self) -> list[int]:
        """The layer segment of each sample (-1: none), a loop: the command's
        segment (its last step row at or before the sample) must be a layer;
        the layer then is the one whose fork range holds the fork (the fork
        turns forward all through these jobs: its layers' ranges follow each other)."""
        layers = [i for i, s in enumerate(self.segments) if s["kind"] == "layer"]
        starts = [self.segments[i]["start"][1] for i in layers]
        assert all(self.segments[i]["delta"][1] > 0 for i in layers) and starts == sorted(starts)
        fork, _ = self.fork()
        out, r = [], -1
        for k, t in enumerate(self.t_ns.tolist()):
            while r + 1 < len(self.rows) and self.rows[r + 1, 0] <= t:
                r += 1
            if r < 0 or self.segments[int(self.rows[r, 1])]["kind"] != "layer":
                out.append(-1)
                continue
            y = fork[k] / self.joint_step[1]
            which = 0
            for n, start in enumerate(starts):
                if start <= y:
                    which = n
            out.append(layers[which])
        return out

    def stress(self, segment: int, at: list[int]) -> list[float]:
        """The stress (Pa) at samples ``at`` of a layer: tension over the bare
        section plus rho v**2 / 2 at the take-up speed of the recorded flyer."""
        seg = self.segments[segment]
        job = self.job
        contour = job.bobbin.contour(job.winding.coils[seg["pole"]].layers[seg["layer"]].radius)
        assert contour is not None
        fork, omega = self.fork()
        section = math.pi * job.wire.bare_diameter**2 / 4
        rho = job.wire.material.density
        out = []
        for k in at:
            psi = fork[k] if omega[k] >= 0 else -fork[k]
            v = abs(omega[k]) * float(contour.lever(np.array([psi]), job.flyer_radius)[0])
            out.append(self.tension[k] / section + rho * v * v / 2)
        return out

    def stretch(self, stress: float) -> tuple[float, float]:
        """The plastic strain and the resistance rise after ``stress``."""
        m = self.job.wire.material
        eps = max(stress - m.yield_stress, 0.0) / m.hardening
        return eps, (1 + eps) ** 2 - 1

    def wire_status(self) -> Any:
        for _, arr in self.diagnostics:
            for status in arr.status:
                if status.name.endswith(": wire"):
                    return status
        return None


def expected_layers(rec: Recorded, until_ns: int | None = None) -> list[dict[str, Any]]:
    layer = rec.layer_of_samples()
    out = []
    for seg in sorted({s for s in layer if s >= 0}):
        at = [k for k, s in enumerate(layer) if s == seg and (until_ns is None or rec.t_ns[k] <= until_ns)]
        if not at:
            continue
        values = [float(rec.tension[k]) for k in at]
        eps, rise = rec.stretch(max(rec.stress(seg, at)))
        out.append(
            {
                "coil": rec.segments[seg]["pole"] + 1,
                "layer": rec.segments[seg]["layer"] + 1,
                "min_n": min(values),
                "mean_n": sum(values) / len(values),
                "max_n": max(values),
                "stretch": eps,
                "resistance_rise": rise,
            }
        )
    return out


def assert_layers(got: list[dict[str, Any]], want: list[dict[str, Any]]) -> None:
    assert [(g["coil"], g["layer"]) for g in got] == [(w["coil"], w["layer"]) for w in want]
    for g, w in zip(got, want, strict=True):
        assert (g["min_n"], g["max_n"]) == (w["min_n"], w["max_n"]), (g, w)
        assert g["mean_n"] == pytest.approx(w["mean_n"], rel=1e-12)
        for key in ("stretch", "resistance_rise"):
            assert g[key] == pytest.approx(w[key], rel=1e-9, abs=1e-15), (key, g, w)


def analyze_json(path: Path) -> dict[str, Any]:
    r = subprocess.run(
        [str(BIN / "winder"), "analyze", str(path), "--no-plots", "--json"],
        capture_output=True, text=True, timeout=180, stdin=subprocess.DEVNULL,
    )  # fmt: skip
    assert r.returncode == 0, r.stderr
    doc: dict[str, Any] = json.loads(r.stdout)[0]
    return doc


# -- the wire object ---------------------------------------------------------------------------


@pytest.mark.ros
def test_a_held_wire_per_layer_and_paid_out(bag: Any) -> None:
    """The session's dancer run: within its bands all through, never past the yield."""
    path = bag("wire")
    rec = Recorded(path)
    wire = analyze_json(path)["wire"]
    assert_layers(wire["layers"], expected_layers(rec))
    assert len(wire["layers"]) == sum(1 for s in rec.segments if s["kind"] == "layer")
    assert all(lay["stretch"] == 0 == lay["resistance_rise"] for lay in wire["layers"])
    assert wire["paid_out_m"] == rec.pos[-1, rec.names.index("supply")] > 0
    assert (wire["tension_min_n"], wire["tension_max_n"]) == (rec.tension.min(), rec.tension.max())
    assert wire["tension_set_n"] == rec.job.set_tension
    assert wire["break"] is None and wire["slip"] is None
    table = format_table([analyze(read_run(path))])
    assert "wire paid out" in table and "wire break" not in table and "wire stretched" not in table


@pytest.mark.ros
def test_a_swinging_wire_is_stretched_per_layer(runs: dict[str, Path]) -> None:
    path = runs["swings"]
    rec = Recorded(path)
    wire = analyze_json(path)["wire"]
    want = expected_layers(rec)
    assert len(want) == 3 and all(w["stretch"] > 0 for w in want), "the run is no test: never past the yield"
    assert_layers(wire["layers"], want)
    assert wire["paid_out_m"] == rec.pos[-1, rec.names.index("supply")]
    assert wire["break"] is None and wire["slip"] is None
    table = format_table([analyze(read_run(path))])
    worst = max(want, key=lambda w: w["stretch"])
    said = f"in 3 of 3 layers, most {100 * worst['stretch']:.3g} % in coil 1 layer {worst['layer']}"
    assert any(line.startswith("wire stretched") and said in line for line in table.splitlines()), table
    assert "wire break" not in table


@pytest.mark.ros
def test_a_broken_wire_is_told_and_ends_the_layers(runs: dict[str, Path]) -> None:
    path = runs["breaks"]
    rec = Recorded(path)
    status = rec.wire_status()
    assert status is not None and int.from_bytes(bytes(np.atleast_1d(status.level)), "little") == 2
    said = {kv.key: kv.value for kv in status.values}
    assert said["fault"] == "break", "the run is no test: its wire did not break"
    t_s = float(said["t_s"])
    wire = analyze_json(path)["wire"]
    assert wire["break"] == {
        "fault": "break", "coil": int(said["coil"]), "layer": int(said["layer"]), "turn": int(said["turn"]),
        "t_s": t_s, "message": status.message,
    }  # fmt: skip
    assert wire["slip"] is None
    # the layers wound up to the break, the last of them cut there
    want = expected_layers(rec, until_ns=round(t_s * 1e9))
    assert [w["layer"] for w in want] == list(range(1, int(said["layer"]) + 1))
    assert_layers(wire["layers"], want)
    table = format_table([analyze(read_run(path))])
    line = f"coil {said['coil']} layer {said['layer']} turn {said['turn']} at {t_s:.3f} s"
    assert any(row.startswith("wire break") and line in row for row in table.splitlines()), table
    assert "wire slip" not in table


@pytest.mark.ros
def test_a_fault_said_only_in_words_and_a_slip(runs: dict[str, Path], tmp_path: Path) -> None:
    """A wire status recorded before its values said where (its message
    alone), and a slip beside it: the break named, nothing of it guessed, the
    layers not cut; the slip read as the break is."""
    path = runs["breaks"]
    rec = Recorded(path)
    slip = {"fault": "slip", "coil": "1", "layer": "1", "turn": "3", "t_s": "0.250000"}
    older = rewritten(path, tmp_path / "older", slip)
    wire = analyze_json(older)["wire"]
    status = rec.wire_status()
    assert wire["break"] == {
        "fault": "break", "coil": None, "layer": None, "turn": None, "t_s": None, "message": status.message
    }  # fmt: skip
    assert wire["slip"] == {
        "fault": "slip", "coil": 1, "layer": 1, "turn": 3, "t_s": 0.25, "message": "wire slip at coil 1"
    }  # fmt: skip
    assert_layers(wire["layers"], expected_layers(rec))
    table = format_table([analyze(read_run(older))])
    rows = {row.split("  ")[0]: row for row in table.splitlines()}
    assert (
        "where not recorded" in rows["wire break"] and "coil 1 layer 1 turn 3 at 0.250 s" in rows["wire slip"]
    )


def rewritten(src: Path, out: Path, slip: dict[str, str]) -> Path:
    """``src`` written again (rosbags) with its wire status's values cut to
    the run's ids (as a status said it before it named the place), and a
    wire status of a slip with ``slip`` beside it."""
    store = jazzy_store()  # Jazzy's types and winder's own (winder/state's CellState)
    kv = store.types["diagnostic_msgs/msg/KeyValue"]
    from rosbags.highlevel import AnyReader

    messages = []
    with AnyReader([src]) as reader:
        for conn, t, raw in reader.messages():
            msg = reader.deserialize(raw, conn.msgtype)
            if conn.topic == "/diagnostics":
                added = []
                for status in msg.status:
                    if status.name.endswith(": wire"):
                        status.values = [v for v in status.values if v.key in ("job_id", "run_id")]
                        values = [*status.values, *(kv(k, v) for k, v in slip.items())]
                        added.append(replace(status, message="wire slip at coil 1", values=values))
                msg.status = [*msg.status, *added]
            messages.append((conn.topic, conn.msgtype, t, msg))
    write_bag(out, messages, StoragePlugin.MCAP)
    return out


# -- the coil as wound: stretched and slack turns ------------------------------------------------


def turn_spans(rec: Recorded, segment: int) -> list[tuple[float, float]]:
    """When the recorded flyer began and ended each turn of a layer (s): the
    times its angle (the most it reached so far) passes each whole turn, a
    loop with linear interpolation between samples."""
    seg = rec.segments[segment]
    fork, _ = rec.fork()
    spr = rec.job.fork_steps_per_rev
    step = rec.joint_step[1]
    reached, progress = -math.inf, []
    for f in fork:
        reached = max(reached, f)
        progress.append(reached)
    t = rec.t_ns / 1e9
    marks = []
    for k in range(seg["delta"][1] // spr + 1):
        goal = (seg["start"][1] + k * spr) * step
        i = next(i for i, p in enumerate(progress) if p >= goal)
        if i == 0 or progress[i] == progress[i - 1]:
            marks.append(t[i])
        else:
            marks.append(
                t[i - 1] + (goal - progress[i - 1]) / (progress[i] - progress[i - 1]) * (t[i] - t[i - 1])
            )
    return list(itertools.pairwise(marks))


@pytest.mark.ros
def test_the_coil_as_wound_marks_stretched_and_slack_turns(runs: dict[str, Path], bag: Any) -> None:
    for path in (runs["swings"], bag("wire")):
        rec = Recorded(path)
        wound = as_wound(read_run(path))
        assert wound is not None
        planned = sum(
            s["delta"][1] // rec.job.fork_steps_per_rev for s in rec.segments if s["kind"] == "layer"
        )
        assert len(wound.turns) == planned
        slack_below = rec.job.set_tension * (1 - rec.job.tension_alarm)
        yield_stress = rec.job.wire.material.yield_stress
        period = float(np.median(np.diff(rec.t_ns))) / 1e9
        # each turn judged on the samples within it: sure where it holds with a sample
        # more or less at either end, else either way
        sure: dict[str, set[tuple[int, int, int]]] = {"stretched": set(), "slack": set()}
        maybe: dict[str, set[tuple[int, int, int]]] = {"stretched": set(), "slack": set()}
        t = rec.t_ns / 1e9
        for i, seg in enumerate(rec.segments):
            if seg["kind"] != "layer":
                continue
            for n, (t0, t1) in enumerate(turn_spans(rec, i)):
                key = (seg["pole"] + 1, seg["layer"] + 1, n + 1)
                for wide, out in ((-period, maybe), (period, sure)):
                    at = [k for k in range(t.size) if t0 + wide <= t[k] < t1 - wide]
                    if not at:
                        continue
                    if max(rec.stress(i, at)) > yield_stress:
                        out["stretched"].add(key)
                    if min(rec.tension[at]) < slack_below:
                        out["slack"].add(key)
        for kind in ("stretched", "slack"):
            got = {(d.coil, d.layer, d.turn) for d in wound.defects if d.kind == kind}
            assert sure[kind] <= got <= maybe[kind], (
                kind,
                sorted(got),
                sorted(sure[kind]),
                sorted(maybe[kind]),
            )
        if path == runs["swings"]:
            assert sure["stretched"] and sure["slack"], "the run is no test: no turn stretched or slack"
        else:
            assert not maybe["stretched"] and not maybe["slack"]
        # --json counts them per layer
        layers = analyze_json(path)["as_wound"]["layers"]
        for kind in ("stretched", "slack"):
            per_layer = {(lay["coil"], lay["layer"]): lay[kind] for lay in layers}
            for (coil, layer), n in per_layer.items():
                assert n == sum(
                    1 for d in wound.defects if d.kind == kind and (d.coil, d.layer) == (coil, layer)
                )


@pytest.mark.ros
def test_wire_png_and_wound_png_are_drawn(runs: dict[str, Path], tmp_path: Path) -> None:
    r = subprocess.run(
        [str(BIN / "winder"), "analyze", str(runs["swings"]), "--plots-dir", str(tmp_path)],
        capture_output=True, text=True, timeout=180, stdin=subprocess.DEVNULL,
    )  # fmt: skip
    assert r.returncode == 0, r.stderr
    for name in ("wire.png", "wound.png"):
        png = tmp_path / name
        assert png.stat().st_size > 10_000 and png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


# -- the stress, a property -------------------------------------------------------------------------

RECT = Job.from_dict(
    {
        "wire_diameter": 0.0005, "wire.bare_diameter": 0.00045, "bobbin.core": "rect",
        "bobbin.core_width": 0.012, "bobbin.core_depth": 0.02, "bobbin.core_corner_radius": 0.001,
        "flyer_radius": 0.03, "turns_per_layer": 6, "layers": 3, "poles": 1, "fork_steps_per_rev": 512,
    }
)  # fmt: skip


@given(
    st.lists(
        st.tuples(st.floats(0.0, 40.0), st.floats(-200.0, 200.0), st.floats(-3000.0, 3000.0)),
        min_size=1,
        max_size=40,
    ),
    st.integers(0, 2),
)
def test_the_stress_is_exact_wherever_it_may_pass_the_yield(
    samples: list[tuple[float, float, float]], layer: int
) -> None:
    """Each sample's stress, against tension / section + rho v**2 / 2 at the
    take-up speed worked out sample by sample: never above it nor below the
    tension's part, and equal to it wherever it passes the yield."""
    seg = [s for s in RECT.segments() if s.kind.winds][layer]
    tension, psi, omega = (np.array(c, dtype=np.float64) for c in zip(*samples, strict=True))
    got = stresses(RECT, seg, tension.copy(), psi, omega)
    wire = RECT.wire
    section = math.pi * wire.bare_diameter**2 / 4
    contour = RECT.bobbin.contour(RECT.winding.coils[0].layers[layer].radius)
    assert contour is not None
    for k, (f, p, w) in enumerate(samples):
        lever = float(contour.lever(np.array([p if w >= 0 else -p]), RECT.flyer_radius)[0])
        exact = f / section + wire.material.density * (abs(w) * lever) ** 2 / 2
        assert f / section <= got[k] <= exact * (1 + 1e-12)
        if exact > wire.material.yield_stress:
            assert got[k] == pytest.approx(exact, rel=1e-12)
