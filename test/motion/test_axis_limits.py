"""Axis limits (winder.motion.limits): a job's peaks against closed forms,
the watch on timed steps against a brute-force loop, and the promise between
them: a job whose peaks are within the limits never trips the watch."""

from __future__ import annotations

import math
import subprocess
from pathlib import Path

import numpy as np
import pytest
from hypothesis import assume, given, settings
from hypothesis import strategies as st
from support.paths import BIN

from winder.contract.params import PROFILE_SPECS
from winder.motion.interp import interpolate_pieces
from winder.motion.job import Job
from winder.motion.limits import NO_LIMIT, QUANTUM, WINDOW_NS, LimitWatch, job_extent, job_limits, job_peaks
from winder.motion.timing import plan_timing

DEFAULT_RAMP = {n: s.default for n, s in PROFILE_SPECS.items()}


#: a small orthocyclic job: each layer a cam of two pieces a turn
ORTHO = {
    "turns_per_layer": 3,
    "layers": 2,
    "poles": 2,
    "lay": "orthocyclic",
    "lay.crossover": 180.0,
    "feed_step": 1e-4,
}


def ramp(**changes: object) -> dict[str, object]:
    return {**DEFAULT_RAMP, **changes}


def test_a_long_trapezoid_move_peaks_at_v_max_and_a_max_times_each_axis_ratio() -> None:
    """One straight move of 3 axes, long enough to cruise: each axis' peak
    velocity is v_max times its share of the major axis' steps times its
    step length; its acceleration a_max times the same; the start speed
    v_start is a jump of v_start times the same (closed forms of the inputs)."""

    class Seg:
        start = (0, 0, 0)
        delta = (300, 10_000, -2_500)
        pieces = (delta,)
        steps = 10_000

    r = ramp(profile="trapezoid", v_max=3000.0, a_max=20000.0, v_start=100.0)
    [timing], _ = plan_timing(r, [Seg.steps])
    step = (1e-5, 2 * math.pi / 1024, 2 * math.pi / 4096)
    peaks = job_peaks([Seg], [timing], step)
    for p, d, s in zip(peaks, Seg.delta, step, strict=True):
        share = abs(d) / 10_000
        assert p.velocity == pytest.approx(3000.0 * share * s, rel=1e-12)
        assert p.acceleration == pytest.approx(20000.0 * share * s, rel=1e-12)
        assert p.jump == pytest.approx(100.0 * share * s, rel=1e-12)
    # an override k: k times the velocity, k^2 the acceleration
    fast = job_peaks([Seg], [timing], step, override=1.5)
    assert fast[1].velocity == pytest.approx(1.5 * peaks[1].velocity, rel=1e-12)
    assert fast[1].acceleration == pytest.approx(2.25 * peaks[1].acceleration, rel=1e-12)


def test_the_default_job_peaks_at_the_documented_flyer_speed() -> None:
    """The RW400 job at the default ramp: the flyer turns 2048 steps/s of
    1024 a turn, 12.566 rad/s (BRIDGE.md); the job refused against a 10 rad/s
    limit in one line naming the axis, the peak and the limit."""
    peaks, why = job_limits(Job(), DEFAULT_RAMP, {"max_velocity.fork": 10.0})
    assert peaks[1].velocity == pytest.approx(2048 * 2 * math.pi / 1024, rel=1e-12)
    assert why == ("the job drives the fork axis at up to 12.5664 rad/s, beyond max_velocity.fork = 10 rad/s")
    assert job_limits(Job(), DEFAULT_RAMP, {"max_velocity.fork": 12.6})[1] == ""
    # a limit a hair below the peak: the digits that tell them apart
    _, why = job_limits(Job(), DEFAULT_RAMP, {"max_velocity.fork": 12.56637})
    assert "at up to 12.5663706 rad/s, beyond max_velocity.fork = 12.56637 rad/s" in why, why
    # a scheduled override counts: 1.2 x 12.566 = 15.08 rad/s
    _, why = job_limits(Job(), DEFAULT_RAMP, {"max_velocity.fork": 13.0}, schedule="override@1=1.2")
    assert "15.0796 rad/s" in why


def test_the_extent_is_the_least_and_greatest_corner() -> None:
    """Brute force: every row of every segment's steps."""
    job = Job.from_dict(ORTHO)
    rows = np.vstack([interpolate_pieces(s.start, s.pieces) for s in job.segments()] + [np.zeros((1, 3))])
    lo, hi = job_extent(job.segments())
    np.testing.assert_array_equal(lo, rows.min(axis=0))
    np.testing.assert_array_equal(hi, rows.max(axis=0))


def brute_watch(
    t: list[int],
    c: list[list[int]],
    start: list[int],
    step: list[float],
    v_max: list[float],
    a_max: list[float],
) -> tuple[int, int, str] | None:
    """The first (row, joint, kind) past a limit, by loops: the count in force
    W and 2W before each row, the differences, the limits widened by whole steps."""
    w = WINDOW_NS / 1e9

    def count_at(when: int, j: int) -> int:
        got = start[j]
        for ti, ci in zip(t, c, strict=True):
            if ti <= when:
                got = ci[j]
        return got

    for i, ti in enumerate(t):
        for j in range(len(start)):
            now, b1, b2 = c[i][j], count_at(ti - WINDOW_NS, j), count_at(ti - 2 * WINDOW_NS, j)
            if abs(now - b1) > v_max[j] / step[j] * w + 2 * QUANTUM:
                return i, j, "velocity"
            if abs(now - 2 * b1 + b2) > a_max[j] / step[j] * w * w + 4 * QUANTUM:
                return i, j, "acceleration"
    return None


@settings(max_examples=150, deadline=None)
@given(
    st.lists(
        st.tuples(st.integers(1, 8_000_000), st.integers(-1, 1), st.integers(-2, 2)), min_size=1, max_size=60
    ),
    st.lists(st.integers(1, 20), min_size=1, max_size=6),
    st.floats(20, 3000),
    st.floats(1e3, 1e6),
)
def test_the_watch_is_the_brute_force_window_however_the_rows_come(
    moves: list[tuple[int, int, int]], cuts: list[int], v_max: float, a_max: float
) -> None:
    """Random rows (time gaps, each joint stepping -1..1 or -2..2), fed in
    random chunks: the watch names the first row and joint the loop does."""
    t, c, at = [], [], [5, -3]
    now = 10**9
    for gap, d0, d1 in moves:
        now += gap
        at = [at[0] + d0, at[1] + d1]
        t.append(now)
        c.append(list(at))
    step, v, a = [0.001, 0.002], [v_max * 0.001, v_max * 0.002], [a_max * 0.001, a_max * 0.002]
    want = brute_watch(t, c, [5, -3], step, v, a)
    watch = LimitWatch([2, 3], np.array([5, -3]), np.array(step), np.array(v), np.array(a))
    rows = np.array([[ti, k, ci[0], ci[1]] for k, (ti, ci) in enumerate(zip(t, c, strict=True))], np.int64)
    got = None
    i = 0
    for n in cuts * 60:
        if i >= len(rows) or got is not None:
            break
        got = watch.feed(rows[i : i + n])
        i += n
    if want is None:
        assert got is None
    else:
        assert got is not None and (got.t_ns, got.joint, got.kind) == (t[want[0]], want[1], want[2])


@settings(max_examples=40, deadline=None)
@given(
    st.sampled_from(["trapezoid", "scurve", "exponential"]),
    st.integers(50, 4000),
    st.integers(-4000, 4000),
    st.floats(500, 8000),
    st.floats(2_000, 200_000),
    st.floats(0.0, 0.3),
    st.sampled_from(["normal", "orthocyclic"]),
)
def test_a_job_within_its_peaks_never_trips_the_watch(
    kind: str, major: int, minor: int, v_max: float, a_max: float, v_start_share: float, lay: str
) -> None:
    """A straight move or a cam-laid job, timed exactly as the profile node
    times it, and the watch set to the peaks job_peaks gives: no step trips
    it. Set to half the peak velocity, a move that cruises for 4 windows
    does trip it."""
    r = ramp(profile=kind, v_max=v_max, a_max=a_max, j_max=a_max * 50, v_start=v_max * v_start_share)
    if lay == "normal":
        assume(abs(minor) <= major)

        class Seg:
            start = (0, 0, 0)
            delta = (minor, major, 0)
            pieces = (delta,)
            steps = major

        segments: list = [Seg]
        step = np.array([1e-5, 2 * math.pi / 1024, 2 * math.pi / 1024])
    else:
        job = Job.from_dict(ORTHO)
        segments = job.segments()
        step = np.array(job.joint_step)
    try:
        timings, _ = plan_timing(r, [s.steps for s in segments])
    except ValueError:
        assume(False)
    peaks = job_peaks(segments, timings, step)
    rows = []
    for seg, timing in zip(segments, timings, strict=True):
        counts = interpolate_pieces(seg.start, seg.pieces)
        times = timing.times_ns(np.arange(1, seg.steps + 1))
        rows.append(np.column_stack([times, np.arange(len(times)), counts]))
    all_rows = np.vstack(rows).astype(np.int64)
    v = np.array([p.velocity for p in peaks])
    a = np.array([p.windowed_acceleration for p in peaks])
    watch = LimitWatch(
        [2, 3, 4], np.zeros(3, np.int64), step, np.where(v > 0, v, NO_LIMIT), np.where(a > 0, a, NO_LIMIT)
    )
    assert watch.feed(all_rows) is None
    # half the peak velocity, on a move that cruises over 4 windows: tripped
    moves = [p for t in timings for p in t.profiles]
    cruising = all(m.duration > 4 * WINDOW_NS / 1e9 for m in moves)
    fork = peaks[1].velocity
    if not (lay == "normal" and cruising and fork / step[1] * WINDOW_NS / 1e9 > 8 * QUANTUM):
        return  # (test_a_job_past_half_its_peak_trips_the_watch holds one such job for sure)
    slow = LimitWatch(
        [2, 3, 4], np.zeros(3, np.int64), step, np.array([NO_LIMIT, fork / 2, NO_LIMIT]), np.full(3, NO_LIMIT)
    )
    over = slow.feed(all_rows)
    assert over is not None and over.kind == "velocity" and over.joint == 1


def check_cli(tmp_path: Path, yaml: str, *args: str) -> subprocess.CompletedProcess[str]:
    limits = tmp_path / "bridge.yaml"
    limits.write_text(yaml)
    return subprocess.run(
        [str(BIN / "winder"), "check", "--limits", str(limits), *args],
        capture_output=True,
        text=True,
        timeout=120,
        stdin=subprocess.DEVNULL,
    )


BRIDGE_YAML = """\
bridge_node:
  ros__parameters:
    joints: [feed_screw, flyer, pole_joint]
    max_position: {feed: 0.05}
    max_velocity: {fork: %s}
    max_acceleration: {fork: 60.0}
controller_manager:
  ros__parameters:
    update_rate: 1000
"""


def test_winder_check_holds_the_job_against_the_bridges_limits(tmp_path: Path) -> None:
    """The default job (flyer 12.566 rad/s, its feed 0..0.05 m) against a
    bridge parameters file (a controller manager's section beside it):
    within, a table and exit 0; a fork limit of 10 rad/s, exit 2 and one
    line naming it; a coil longer than max_position.feed, exit 2; a bad
    value or no bridge section, one line naming it, no traceback."""
    ok = check_cli(tmp_path, BRIDGE_YAML % "15.0")
    assert ok.returncode == 0, ok.stderr
    assert "within limits  yes" in ok.stdout
    fork = next(line for line in ok.stdout.splitlines() if line.strip().startswith("fork"))
    assert "12.5664" in fork and "15" in fork
    fast = check_cli(tmp_path, BRIDGE_YAML % "10.0")
    assert fast.returncode == 2
    assert fast.stderr.strip().splitlines() == [
        "winder check: error: the job drives the fork axis at up to 12.5664 rad/s, "
        "beyond max_velocity.fork = 10 rad/s"
    ]
    far = check_cli(tmp_path, BRIDGE_YAML % "15.0", "--turns-per-layer", "30")
    assert far.returncode == 2 and "beyond max_position.feed = 0.05 m" in far.stderr, far.stderr
    bad = check_cli(tmp_path, BRIDGE_YAML % "-1.0")
    assert bad.returncode == 2 and len(bad.stderr.strip().splitlines()) == 1, bad.stderr
    assert "max_velocity.fork=-1" in bad.stderr and "Traceback" not in bad.stderr
    none = check_cli(tmp_path, "other_node:\n  ros__parameters: {a: 1}\n")
    assert none.returncode == 2 and "no section for bridge_node" in none.stderr, none.stderr


def test_winder_check_counts_the_jobs_scheduled_override_and_refuses_unclear_limits(tmp_path: Path) -> None:
    """A job file whose schedule raises the feed override to 1.8: the fork's
    peak is 1.8 x 12.566 = 22.62 rad/s, past a 20 rad/s limit (before: 12.566,
    "within limits yes"). Two cells' bridge sections in one file, or one
    limit given twice, are refused as unclear; so is an empty --limits."""
    job = tmp_path / "job.yaml"
    job.write_text('interp_node:\n  ros__parameters:\n    schedule: "override@0.5=1.8"\n')
    fast = check_cli(tmp_path, BRIDGE_YAML % "20.0", str(job))
    assert fast.returncode == 2, fast.stdout + fast.stderr
    peak = 1.8 * 2048 * 2 * math.pi / 1024
    assert (
        f"at up to {peak:.6g} rad/s, beyond max_velocity.fork = 20 rad/s, at feed override 1.8" in fast.stderr
    )
    two = "/cell1/bridge_node:\n  ros__parameters: {max_velocity: {fork: 10.0}}\n"
    two += "/cell2/bridge_node:\n  ros__parameters: {max_velocity: {fork: 20.0}}\n"
    unclear = check_cli(tmp_path, two)
    assert unclear.returncode == 2 and "all name bridge_node" in unclear.stderr, unclear.stderr
    twice = check_cli(
        tmp_path,
        "bridge_node:\n  ros__parameters:\n    max_velocity.fork: 10.0\n    max_velocity: {fork: 20.0}\n",
    )
    assert twice.returncode == 2 and "max_velocity.fork is given twice" in twice.stderr, twice.stderr
    empty = subprocess.run(
        [str(BIN / "winder"), "check", "--limits", ""], capture_output=True, text=True, timeout=120
    )
    assert empty.returncode == 2 and "--limits is empty" in empty.stderr, empty.stderr


def test_a_job_past_half_its_peak_trips_the_watch() -> None:
    """A 20-turn layer at the default ramp (2048 steps/s, 1024 a turn: the
    flyer at 12.566 rad/s): with max_velocity at half that the watch names
    the fork's velocity; at the peak itself nothing."""
    job = Job(turns_per_layer=20, layers=1, poles=1)
    [seg] = job.segments()
    [timing], _ = plan_timing(DEFAULT_RAMP, [seg.steps])
    rows = np.column_stack(
        [
            timing.times_ns(np.arange(1, seg.steps + 1)),
            np.zeros(seg.steps),
            interpolate_pieces(seg.start, seg.pieces),
        ]
    ).astype(np.int64)
    step = np.array(job.joint_step)
    peak = 2048 * 2 * math.pi / 1024
    none = np.full(3, NO_LIMIT)
    at_peak = LimitWatch([2, 3, 4], np.zeros(3, np.int64), step, np.array([NO_LIMIT, peak, NO_LIMIT]), none)
    assert at_peak.feed(rows) is None
    half = LimitWatch([2, 3, 4], np.zeros(3, np.int64), step, np.array([NO_LIMIT, peak / 2, NO_LIMIT]), none)
    over = half.feed(rows)
    assert over is not None and (over.kind, over.joint) == ("velocity", 1)
    assert peak / 2 < over.value <= peak + 3 * step[1] / (WINDOW_NS / 1e9)
