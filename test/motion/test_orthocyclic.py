"""Orthocyclic lay, the reversal dwell and the slower first layer: the cam of
the flyer against the rules written again here (turn places, crossover
zones, the climb to the next layer, a brute-force minimum-deviation walk of
every piece), its refusals, the timing of the first layer, the stream check
of a cam layer, and real runs through the three nodes read back from their
bags."""

from __future__ import annotations

import itertools
import json
import math
import re
import subprocess
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from conftest import BIN, Procs, closed_bags, rosbags_read
from hypothesis import HealthCheck, assume, example, given, settings
from hypothesis import strategies as st
from support.paths import ROOT

from winder.contract.eq7 import step_deviation
from winder.contract.params import PROFILE_SPECS
from winder.contract.stream import StreamChecker, describe_job, parse_job_description
from winder.motion.interp import interpolate, interpolate_pieces
from winder.motion.job import Job, JobError
from winder.motion.timeline import Command, Timeline
from winder.motion.timing import plan_timing
from winder.record.reader import read_run

JOBS = ROOT / "jobs"


# -- the rules, written again -------------------------------------------------
def brute_min_deviation(dx: int, dy: int) -> list[tuple[int, int]]:
    """The paper's rule, literally: the major axis always steps; the minor
    joins it iff that makes |F| = |dx*y - x*dy| smaller."""
    sx, sy = (dx > 0) - (dx < 0), (dy > 0) - (dy < 0)
    x_major = abs(dx) >= abs(dy)
    x = y = 0
    out = []
    for _ in range(max(abs(dx), abs(dy))):
        alone = (x + sx, y) if x_major else (x, y + sy)
        both = (x + sx, y + sy)
        x, y = both if abs(dx * both[1] - both[0] * dy) < abs(dx * alone[1] - alone[0] * dy) else alone
        out.append((x, y))
    return out


def steps_of(metres: float, feed_step: float) -> int:
    """A length in feed steps, to the nearest step, halves up (the job's rounding rule)."""
    return math.floor(metres / feed_step * (1 + 1e-9) + 0.5)


def expected_layer(job: Job, pole: int, layer: int, origin: int, first: int) -> list[tuple[int, int]]:
    """(feed, fork progress) waypoints of a layer from the rules: odd layers'
    turns k at k*d from the coil's first turn, even layers' at (k + 1/2)*d;
    the feed holds a turn and crosses over to the next in
    [r*spr + at, r*spr + at + zone) of turn r; after the last turn and the
    dwell the wire climbs to the next layer's first turn in the layer's last
    whole zone."""
    d, fs, spr = job.wire_diameter, job.feed_step, job.fork_steps_per_rev
    geometry = job.winding.coils[pole].layers
    n = geometry[layer].turns
    shift = 0.5 if layer % 2 else 0.0
    places = [origin + first * steps_of((k + shift) * d, fs) for k in range(n)]
    if layer % 2:
        places.reverse()  # the even layers are wound back
    at = math.floor(job.crossover_at / 360 * spr + 0.5)
    zone = max(1, math.floor(job.crossover / 360 * spr + 0.5))
    end = n * spr + math.floor(job.reversal_dwell * spr + 0.5)
    points = [(places[0], 0)]

    def crossing(a: int, b: int, k0: int) -> list[tuple[int, int]]:
        """From feed a to b over the zone from fork k0: a straight line
        (linear), or the cycloid u - sin(2 pi u)/(2 pi) through min(16, zone)
        + 1 points rounded to whole steps."""
        if job.crossover_law == "linear" or a == b:
            return [(a, k0), (b, k0 + zone)]
        n_pts = min(16, zone)
        return [
            (
                a
                + math.floor((b - a) * (i / n_pts - math.sin(2 * math.pi * i / n_pts) / (2 * math.pi)) + 0.5),
                k0 + math.floor(zone * i / n_pts + 0.5),
            )
            for i in range(n_pts + 1)
        ]

    for r in range(n - 1):
        points += crossing(places[r], places[r + 1], r * spr + at)
    if layer + 1 < len(geometry):
        m = geometry[layer + 1].turns
        nxt_k = 0 if (layer + 1) % 2 == 0 else m - 1
        nxt = origin + first * steps_of((nxt_k + (0.5 if (layer + 1) % 2 else 0.0)) * d, fs)
        r = (end - at - zone) // spr
        points += crossing(places[-1], nxt, r * spr + at)
    points.append((points[-1][0], end))
    return points


def walk(points: list[tuple[int, int]], fork_sign: int) -> list[tuple[int, int]]:
    """Every step from waypoint to waypoint by the brute-force rule: (feed, fork progress)."""
    out: list[tuple[int, int]] = []
    for (x0, u0), (x1, u1) in itertools.pairwise(points):
        out += [(x0 + dx, fork_sign * (u0 + du)) for dx, du in brute_min_deviation(x1 - x0, u1 - u0)]
    return out


@st.composite
def ortho_jobs(draw: st.DrawFn) -> dict[str, Any]:
    """The settings of an orthocyclic job (its turns laid in a layer of
    their own, or as many as fit a window); the job is the test's to make."""
    per_d = draw(st.integers(2, 12))  # feed steps per wire diameter
    spr = draw(st.sampled_from([16, 24, 64, 100, 256]))
    d = draw(st.sampled_from([0.2e-3, 0.5e-3, 1.0e-3, 2.0e-3]))
    law = draw(st.sampled_from(["cycloidal", "linear"]))
    # the cycloid's peak speed is twice its mean (and a whole step more, rounded)
    need = math.ceil((per_d if law == "linear" else 2 * per_d + 2) / spr * 3600) / 10 + 0.1
    assume(need < 300)
    zone = draw(st.floats(need, 360.0))
    at = draw(st.floats(0.0, 360.0 - zone))
    layers = draw(st.integers(1, 4))
    dwell = draw(st.sampled_from([0.0, 0.5, 1.0, 2.25]))
    values: dict[str, Any] = {
        "lay": "orthocyclic",
        "wire_diameter": d,
        "feed_step": d / per_d,
        "fork_steps_per_rev": spr,
        "lay.crossover": zone,
        "lay.crossover_at": at,
        "lay.crossover_law": law,
        "layers": layers,
        "reversal_dwell": dwell,
        "poles": draw(st.integers(1, 2)),
        "flyer_radius": 0.1,
    }
    if draw(st.booleans()):
        values["turns_per_layer"] = draw(st.integers(1, 6))
    else:  # auto: a window of n1 wire diameters and a random part of one
        n1 = draw(st.integers(1, 6))
        values["turns_per_layer"] = "auto"
        values["bobbin.window_width"] = (n1 + draw(st.sampled_from([0.0, 0.3, 0.5, 0.7]))) * d
    if values["poles"] == 2 and draw(st.booleans()):
        values["coil_overrides"] = "2:direction=ccw"
    return values


#: found by hypothesis: 9 feed steps a wire diameter crossed over 21 fork steps.
#: The cycloid's peak is 0.86 feed steps a fork step, and forward its points
#: round to pieces the flyer leads; back (the second layer) they round to a
#: piece of 2 feed steps in 1 fork step, and the job was taken
BACK_CROSSOVER = {
    "wire_diameter": 0.0002,
    "flyer_radius": 0.1,
    "turns_per_layer": 2,
    "layers": 2,
    "poles": 1,
    "fork_steps_per_rev": 256,
    "feed_step": 2.2222222222222223e-05,
    "lay": "orthocyclic",
    "lay.crossover": 29.0,
}


def refused_for_its_crossover(values: dict[str, Any]) -> bool:
    """Whether the job of ``values`` is refused, in one line; a layer that
    holds no turn is not the cam tests' subject (rejected), a crossover
    zone too short for the cam as it is laid is (the strategy's zone, from
    the cycloid's peak, is a guess at it)."""
    try:
        Job.from_dict(values)
    except JobError as exc:
        text = str(exc)
        assert "\n" not in text, text
        assume("holds no turn" not in text and "fit" not in text)
        assert "lay.crossover=" in text and "is too short" in text, text
        return True
    return False


@settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(ortho_jobs())
@example(BACK_CROSSOVER)
def test_the_cam_is_the_rules_written_again(values: dict[str, Any]) -> None:
    if refused_for_its_crossover(values):
        return
    job = Job.from_dict(values)
    segs = job.segments()
    position = np.array(segs[0].start)
    origins: dict[int, tuple[int, int]] = {}
    for seg in segs:
        assert tuple(position) == seg.start, "a move starts where the last one ended"
        rows = interpolate_pieces(seg.start, seg.pieces)
        if seg.kind == "layer":
            if seg.pole not in origins:
                first = 1 if job.segments()[seg.index].delta[0] >= 0 else -1
                if seg.delta[0] == 0:
                    first = next((1 if p[0] > 0 else -1 for p in seg.pieces if p[0]), 1)
                origins[seg.pole] = (seg.start[0], first)
            origin, first = origins[seg.pole]
            sign = job.coil(seg.pole).direction
            want = walk(expected_layer(job, seg.pole, seg.layer, origin, first), sign)
            got = [(int(r[0]), int(r[1]) - seg.start[1]) for r in rows]
            assert got == want, (seg.pole, seg.layer)
            # the fork steps on every row; the feed only inside a crossover zone
            fork = np.abs(np.diff(np.concatenate([[seg.start[1]], rows[:, 1]])))
            assert np.all(fork == 1)
            feed_moves = np.flatnonzero(np.diff(np.concatenate([[seg.start[0]], rows[:, 0]])))
            spr = job.fork_steps_per_rev
            at = math.floor(job.crossover_at / 360 * spr + 0.5)
            zone = max(1, math.floor(job.crossover / 360 * spr + 0.5))
            within = (feed_moves % spr) - at  # the row's step ends fork progress u = index + 1
            assert np.all((within >= 0) & (within < zone)), "the feed moved outside a crossover zone"
        position = rows[-1] if rows.size else position


def cycloid_leads(across: int, z: int) -> bool:
    """Whether the flyer leads every piece of a cycloidal crossover of
    ``across`` feed steps (signed) over ``z`` fork steps: the cycloid through
    min(16, z) + 1 points rounded to whole steps (halves up)."""
    n = min(16, z)
    pts = [
        (
            math.floor(across * (i / n - math.sin(2 * math.pi * i / n) / (2 * math.pi)) + 0.5),
            math.floor(z * i / n + 0.5),
        )
        for i in range(n + 1)
    ]
    return all(abs(f1 - f0) <= k1 - k0 for (f0, k0), (f1, k1) in itertools.pairwise(pts))


def shortest_cycloid_zone(*across: int, start: int = 1) -> int:
    """The fewest fork steps, ``start`` at least, over which cycloidal
    crossovers of each of ``across`` feed steps take the flyer leading every
    piece, forward and back: brute force over z."""
    for z in range(start, 10 * max(across)):
        if all(cycloid_leads(s * a, z) for a in across for s in (1, -1)):
            return z
    raise AssertionError("no zone")


@pytest.mark.parametrize("law", ["linear", "cycloidal"])
def test_a_crossover_zone_too_short_is_refused_naming_the_shortest_that_would_do(law: str) -> None:
    base = {
        "lay": "orthocyclic",
        "turns_per_layer": 5,
        "poles": 1,
        "lay.crossover_law": law,
    }  # 250 per d, 1024 a turn
    with pytest.raises(JobError) as err:
        Job.from_dict({**base, "lay.crossover": 60.0})
    text = str(err.value)
    assert (
        "\n" not in text
        and "lay.crossover=60 deg is too short" in text
        and f"lay.crossover_law {law}" in text
    )
    need = float(re.search(r"shortest crossover zone that would do is ([0-9.]+) deg", text).group(1))  # type: ignore[union-attr]
    # a turn's crossover is 250 feed steps, a climb's 125
    steps = 250 if law == "linear" else shortest_cycloid_zone(250, 125)  # linear: 87.9 deg, 250 fork steps
    assert need == math.ceil(steps / 1024 * 3600) / 10
    assert law == "linear" or steps > 1.9 * 250  # the cycloid peaks at twice its mean speed (1.97 a piece)
    Job.from_dict({**base, "lay.crossover": need})  # the zone it names does
    with pytest.raises(JobError, match="crossover_at \\+ crossover <= 360"):
        Job.from_dict({**base, "lay.crossover": 100.0, "lay.crossover_at": 300.0})


def test_a_crossover_the_flyer_leads_forward_but_not_back_is_refused() -> None:
    """:data:`BACK_CROSSOVER`: refused in one line naming the shortest zone
    that would do, found here by brute force over the crossovers its cam
    lays (9 feed steps a turn, 4 or 5 a climb, each way); with that zone
    every step of the cam steps the fork."""
    assert cycloid_leads(9, 21) and not cycloid_leads(-9, 21)
    with pytest.raises(JobError) as err:
        Job.from_dict(BACK_CROSSOVER)
    text = str(err.value)
    assert "\n" not in text and "lay.crossover=29 deg is too short" in text, text
    need = float(re.search(r"shortest crossover zone that would do is ([0-9.]+) deg", text).group(1))  # type: ignore[union-attr]
    # from the zone given up (rounded to whole steps, a zone's pieces differ with its length: 15 fork
    # steps would do, 21 to 25 not, 26 does)
    steps = shortest_cycloid_zone(9, 5, 4, start=21)
    assert need == math.ceil(steps / 256 * 3600) / 10
    job = Job.from_dict({**BACK_CROSSOVER, "lay.crossover": need})
    assert job.crossover_zone[1] == steps
    for seg in job.segments():
        rows = interpolate_pieces(seg.start, seg.pieces)
        assert np.all(np.abs(np.diff(np.concatenate([[seg.start[1]], rows[:, 1]]))) == 1)


def test_a_dwell_needs_the_flyer_to_lead() -> None:
    with pytest.raises(JobError, match="reversal_dwell=1 is invalid with feed_step"):
        Job.from_dict({"reversal_dwell": 1.0, "feed_step": 1e-6, "fork_steps_per_rev": 64})


def test_a_helical_dwell_holds_the_feed_at_the_flange() -> None:
    job = Job.from_dict({"reversal_dwell": 2.0, "turns_per_layer": 3, "layers": 2, "poles": 1})
    spr = job.fork_steps_per_rev
    for seg in job.segments():
        rows = interpolate_pieces(seg.start, seg.pieces)
        line = interpolate(seg.start, (seg.delta[0], 3 * spr, 0))
        assert np.array_equal(rows[: 3 * spr], line), "the layer's turns are today's helix"
        assert np.all(rows[3 * spr :, 0] == line[-1, 0]) and rows.shape[0] == 5 * spr


def peak_rate(motion: Any) -> float:
    t = np.linspace(0.0, motion.duration, 20001)
    return float(np.max(motion.sample(t)[1]))


def test_the_first_layer_runs_at_its_fraction_of_v_max_even_under_an_override() -> None:
    job = Job.from_dict({"first_layer_speed": 0.4, "turns_per_layer": 20, "layers": 2, "poles": 2})
    values = {name: spec.default for name, spec in PROFILE_SPECS.items()}
    segs = job.segments()
    speeds = [job.segment_speed(s) for s in segs]
    assert speeds == [0.4, 1.0, 1.0, 0.4, 1.0]  # layer 1 of each coil; the index move at full speed
    timing, total = plan_timing(values, [s.steps for s in segs], speeds=speeds)
    for s, t in zip(segs, timing, strict=True):
        if s.kind == "layer":  # long enough to reach its top speed (a pole index is not)
            v = values["v_max"] * (0.4 if s.layer == 0 else 1.0)
            assert peak_rate(t.profiles[0]) == pytest.approx(v, rel=1e-6)
    _, plain = plan_timing(values, [s.steps for s in segs])
    assert total > plain
    # an override of 1.5 in the middle of the first layer: 1.5 x 0.4 x v_max from then on
    line = Timeline(values, timing)
    mid = timing[0].profiles[0].duration / 2
    line.apply(Command(round(mid * 1e9), "override", 1.5))
    k = np.arange(1, segs[0].steps + 1)
    times, n = line.times_ns(0, k)
    assert n == k.size
    rate = 1e9 / np.diff(times[k.size // 2 :])
    assert np.max(rate) <= 1.5 * 0.4 * values["v_max"] * 1.01
    assert np.max(rate) >= 1.5 * 0.4 * values["v_max"] * 0.95


def test_the_stream_check_follows_the_cam_and_refuses_the_straight_line() -> None:
    job = Job.from_dict(
        {"lay": "orthocyclic", "lay.crossover": 180.0, "turns_per_layer": 4, "layers": 2, "poles": 1}
    )
    plan = parse_job_description(describe_job(job))
    checker = StreamChecker(plan)
    for seg in job.segments():
        rows = interpolate_pieces(seg.start, seg.pieces)
        for lo in range(0, rows.shape[0], 700):
            assert checker.check(seg.index, rows[lo : lo + 700]).accept
        # the commanded steps lie on the cam: within a feed step of its pieces
        assert np.max(step_deviation(plan, seg.index, rows)) <= job.feed_step
    assert checker.complete and checker.missing == 0
    fresh = StreamChecker(plan)
    seg = job.segments()[0]
    straight = interpolate(seg.start, seg.delta, stop=500)
    verdict = fresh.check(0, straight)
    assert not verdict.accept and "is not on the job's path" in verdict.message


# -- real runs ------------------------------------------------------------------


def winder_run(
    procs: Procs, bags: Path, *args: str, timeout: float = 240
) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [str(BIN / "winder"), "run", "--bag-dir", str(bags), *args],
        env=procs.env, capture_output=True, text=True, timeout=timeout, stdin=subprocess.DEVNULL,
    )  # fmt: skip


def analyze_json(bag: Path, plots: bool = False) -> dict[str, Any]:
    r = subprocess.run(
        [str(BIN / "winder"), "analyze", str(bag), "--json", *(() if plots else ("--no-plots",))],
        capture_output=True, text=True, timeout=120, stdin=subprocess.DEVNULL,
    )  # fmt: skip
    assert r.returncode == 0, r.stderr
    doc: dict[str, Any] = json.loads(r.stdout)[0]
    return doc


#: the operations a run takes, which a cam layer must keep: programmed stops, a
#: pause and its resume, an override, and a shaped ramp
OPERATED = (
    "--stops", "1:30,1:100", "--stop-pause", "0.3", "--schedule", "pause@10,resume@11,override@20=1.3",
    "--shaper", "zvd",
)  # fmt: skip


@pytest.mark.ros
@pytest.mark.parametrize("extra", [(), OPERATED], ids=["plain", "operated"])
def test_an_orthocyclic_coil_runs_exact_and_is_laid_in_the_grooves(
    procs: Procs, tmp_path: Path, extra: tuple[str, ...]
) -> None:
    job_file = JOBS / "ortho_round.yaml"
    r = winder_run(procs, tmp_path / "bags", str(job_file), "--layers", "3", *extra)
    assert r.returncode == 0, r.stdout + r.stderr
    assert "missing 0, gaps 0" in r.stdout and re.search(r"lost steps\s+0 full steps", r.stdout), r.stdout
    [bag] = closed_bags(tmp_path / "bags")
    run = read_run(bag)
    job = run.plan.job
    assert job.lay == "orthocyclic" and run.complete
    if extra:  # the operator's pause, resume and override were taken (the stops are the profile's own)
        events = [m.event for _, m in rosbags_read(bag)["/winder/control"]]
        assert events == ["pause", "resume", "override"]
    rows = run.steps
    # every step the job's, exactly: the interp node's cam, row for row
    want = np.concatenate([interpolate_pieces(s.start, s.pieces) for s in job.segments()])
    assert np.array_equal(rows[:, 2:5], want)
    # the feed held outside the crossover zones (and the climb's)
    spr = job.fork_steps_per_rev
    at = math.floor(job.crossover_at / 360 * spr + 0.5)
    zone = math.floor(job.crossover / 360 * spr + 0.5)
    moved = np.flatnonzero(np.diff(rows[:, 2])) + 1  # rows whose step moved the feed
    progress = np.abs(rows[moved, 3]) - 1  # the fork position before the step, from the coil's start
    assert np.all((progress % spr >= at) & (progress % spr < at + zone))
    # as wound: 60/59/60 turns, each in its groove (odd layers (k + 1/2) d, even (k + 1) d), no defect
    doc = analyze_json(bag)["as_wound"]
    assert doc["turns_per_layer"] == [[60, 59, 60]] and doc["defects"] == []
    d = job.wire_diameter
    assert [lay["radial_m"] for lay in doc["layers"]] == pytest.approx(
        [d / 2 + i * d * math.sqrt(3) / 2 for i in range(3)]
    )
    from winder.analysis.wound import as_wound

    wound = as_wound(run)
    assert wound is not None
    for turn in wound.turns:
        k = turn.turn - 1
        n = 59 if turn.layer == 2 else 60
        place = (k + 0.5) * d if turn.layer % 2 == 1 else (n - k) * d  # the even layer wound back
        assert turn.intended_m == pytest.approx(place, abs=job.feed_step), turn
        assert abs(turn.axial_m - place) < 0.1 * d


@pytest.mark.ros
def test_a_dwell_and_a_slow_first_layer_run_as_asked(procs: Procs, tmp_path: Path) -> None:
    r = winder_run(
        procs, tmp_path / "bags", "--job-id", "dwell", "--turns-per-layer", "5", "--layers", "2",
        "--poles", "1", "--reversal-dwell", "2", "--first-layer-speed", "0.5",
    )  # fmt: skip
    assert r.returncode == 0, r.stdout + r.stderr
    [bag] = closed_bags(tmp_path / "bags")
    run = read_run(bag)
    rows = run.steps
    spr = run.plan.job.fork_steps_per_rev
    v_max = PROFILE_SPECS["v_max"].default
    for seg in (0, 1):
        mine = rows[rows[:, 1] == seg]
        assert mine.shape[0] == 7 * spr  # five turns and two of dwell
        assert np.all(mine[5 * spr - 1 :, 2] == mine[-1, 2]), "the feed holds for the dwell"
        rate = 1e9 / np.diff(mine[:, 0])
        top = v_max * (0.5 if seg == 0 else 1.0)
        assert top * 0.99 <= np.max(rate) <= top * 1.001, (seg, np.max(rate))


@pytest.mark.ros
def test_a_feed_that_loses_steps_in_the_crossovers_shows_as_defects(procs: Procs, tmp_path: Path) -> None:
    # a feed motor at 0.3 A (of 1) cannot follow the linear crossover's jump to the flyer's step rate
    r = winder_run(
        procs, tmp_path / "bags", "--job-id", "orthoslip", "--lay", "orthocyclic", "--lay.crossover", "90",
        "--lay.crossover-law", "linear",
        "--turns-per-layer", "6", "--layers", "2", "--poles", "1", "--model", "nonlinear",
        "--feed.i-a", "0.3", "--publish-rate", "2000",
    )  # fmt: skip
    assert r.returncode in (1, 6), r.stdout + r.stderr  # 6: done with lost steps (1: and a stall besides)
    [bag] = closed_bags(tmp_path / "bags")
    report = analyze_json(bag, plots=True)  # wound.png too: every kind of defect has its colour
    assert (bag / "plots" / "wound.png").stat().st_size > 0
    assert int(report["lost_steps"]) > 0
    defects = report["as_wound"]["defects"]
    assert defects, "a feed that lost steps laid no defect"
    first = defects[0]
    # where the feed first left its command by more than the tolerance, from the raw samples
    run = read_run(bag)
    cmd, act = run.commands, run.states
    assert np.array_equal(cmd.t, act.t)
    tol = report["as_wound"]["tolerance_m"]
    off = np.flatnonzero(np.abs(act.pos[:, 0] - cmd.pos[:, 0]) > tol)
    assert off.size, "the feed never left its command: the run is no test"
    turn_of_loss = act.pos[off[0], 1] / (2 * math.pi)  # the flyer's turns from the start
    # the loss happened in the crossover after turn k: turn k + 1 (from 1) is the first laid off its place
    assert first["layer"] == 1 and first["turn"] - 1 <= turn_of_loss + 1 <= first["turn"] + 1, (
        first,
        turn_of_loss,
    )


def test_every_defect_kind_has_a_colour_and_a_word_in_wound_png() -> None:
    from winder.analysis.figures.analysis import WOUND_COLOURS, WOUND_WORDS
    from winder.analysis.wound import DEFECT_KINDS

    assert set(DEFECT_KINDS) <= set(WOUND_COLOURS) and set(DEFECT_KINDS) <= set(WOUND_WORDS)


def windowed_feed_acceleration(rows: np.ndarray, window_s: float) -> float:
    """The feed's largest acceleration over ``window_s`` in recorded step rows
    (t ns, segment, feed, fork, pole): at each row's time, the change of the
    mean velocity over the window before it from the window before that."""
    t = rows[:, 0] / 1e9
    feed = rows[:, 2].astype(float)

    def at(times: np.ndarray) -> np.ndarray:  # the feed's position at times: its last step's
        k = np.searchsorted(t, times, side="right") - 1
        return np.where(k >= 0, feed[np.maximum(k, 0)], feed[0])

    now = t[t >= t[0] + 2 * window_s]
    accel = (at(now) - 2 * at(now - window_s) + at(now - 2 * window_s)) / window_s**2
    return float(np.abs(accel).max())


@pytest.mark.ros
def test_the_cycloidal_crossover_keeps_the_feed_within_a_limit_the_linear_one_passes(
    procs: Procs, tmp_path: Path
) -> None:
    """The same job with either cam law: with a feed acceleration limit at
    what the cycloidal law needs (`winder check --limits`), the cycloidal job
    fits and its recorded steps keep within it over every 20 ms; the linear
    one is refused, and its recorded steps do pass the limit."""
    from winder.motion.limits import WINDOW_S, job_limits

    fields = {
        "job_id": "cam", "lay": "orthocyclic", "wire_diameter": 0.0005, "feed_step": 1e-6,
        "fork_steps_per_rev": 2048, "lay.crossover": 180.0, "turns_per_layer": 4, "layers": 1, "poles": 1,
        "flyer_radius": 0.03,
    }  # fmt: skip
    job_file = tmp_path / "cam.yaml"
    job_file.write_text(
        "interp_node:\n  ros__parameters:\n"
        + "".join(f"    {k}: {v!r}\n" for k, v in fields.items()).replace("'", "")
        + "profile_node:\n  ros__parameters:\n    v_max: 6000.0\n"
    )
    args = [str(job_file)]
    values = {n: s.default for n, s in PROFILE_SPECS.items()} | {"v_max": 6000.0}
    need = job_limits(Job.from_dict(fields), values, {})[0][0].windowed_acceleration
    limits = tmp_path / "limits.yaml"
    limits.write_text(f"bridge_node:\n  ros__parameters:\n    max_acceleration.feed: {need * 1.01!r}\n")
    measured = {}
    for law in ("cycloidal", "linear"):
        check = subprocess.run(
            [str(BIN / "winder"), "check", *args, "--lay.crossover-law", law, "--limits", str(limits)],
            capture_output=True, text=True, timeout=120,
        )  # fmt: skip
        assert check.returncode == (0 if law == "cycloidal" else 2), check.stdout + check.stderr
        r = winder_run(procs, tmp_path / law, *args, "--lay.crossover-law", law)
        assert r.returncode == 0, r.stdout + r.stderr
        [bag] = closed_bags(tmp_path / law)
        measured[law] = windowed_feed_acceleration(read_run(bag).steps, WINDOW_S) * 1e-6  # m/s2
    # whole steps: each of the three positions off the ideal by up to 1.5 steps
    whole = 4 * 1.5 / WINDOW_S**2 * 1e-6
    assert measured["cycloidal"] <= need + whole
    assert measured["linear"] > need * 1.01
    assert measured["linear"] > 1.2 * measured["cycloidal"]  # a jump at each end against none
