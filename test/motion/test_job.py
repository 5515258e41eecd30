"""Winding jobs: expansion into segments and validation as users see it."""

from __future__ import annotations

import itertools
import math
import subprocess
import sys

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from winder.motion.interp import interpolate
from winder.motion.job import FIELD_SPECS, Job, JobError
from winder.spec import SpecError


def test_default_job_is_the_rw400_setup() -> None:
    job = Job()
    assert job.flyer_radius == 0.5
    assert job.wire_diameter == 2.5e-3
    assert job.fork_steps_per_rev == 2**10
    # fork arc per step at a 500 mm flyer: 2*pi*0.5/1024
    assert job.step_lengths[1] == pytest.approx(math.pi / 1024)


def test_the_job_in_one_phrase_counts_in_the_singular_and_plural() -> None:
    """Reports name a job by its shape: "1 pole x 1 layer", never "1 poles"."""
    assert Job().shape == "4 poles x 2 layers x 20 turns"
    assert Job(poles=1, layers=1, turns_per_layer=1).shape == "1 pole x 1 layer x 1 turn"
    assert Job(poles=2, layers=1, turns_per_layer=3).shape == "2 poles x 1 layer x 3 turns"


@settings(max_examples=60, deadline=None)
@given(
    turns=st.integers(1, 30),
    layers=st.integers(1, 5),
    poles=st.integers(1, 9),
    fork=st.integers(4, 2000),
    pole_res=st.integers(4, 5000),
    wire_um=st.integers(50, 5000),
    feed_um=st.integers(1, 50),
)
def test_segments_walk_the_job(
    turns: int, layers: int, poles: int, fork: int, pole_res: int, wire_um: int, feed_um: int
) -> None:
    job = Job(
        turns_per_layer=turns,
        layers=layers,
        poles=poles,
        fork_steps_per_rev=fork,
        pole_steps_per_rev=pole_res,
        wire_diameter=wire_um * 1e-6,
        feed_step=feed_um * 1e-6,
    )
    segs = job.segments()
    assert len(segs) == poles * layers + poles - 1
    pos = np.zeros(3, dtype=np.int64)
    feed_dirs = []
    for i, seg in enumerate(segs):
        assert seg.index == i
        assert tuple(pos) == seg.start  # segments are contiguous
        if seg.kind == "layer":
            assert seg.delta[1] == turns * fork
            assert abs(seg.delta[0]) == (2 * turns * wire_um + feed_um) // (2 * feed_um)  # halves up
            assert seg.delta[2] == 0
            feed_dirs.append(np.sign(seg.delta[0]))
        else:
            assert seg.delta[:2] == (0, 0)
        pos += seg.delta
    # the feed reverses at every layer
    assert all(a == -b for a, b in itertools.pairwise(feed_dirs))
    # the fork only ever turns forward: one revolution per turn
    assert pos[1] == poles * layers * turns * fork
    # indexing: coil p sits at the nearest step to p/poles of a revolution
    assert pos[2] == round((poles - 1) * pole_res / poles)
    assert job.total_steps == sum(max(abs(d) for d in s.delta) for s in segs)


def test_small_job_steps_end_where_the_job_ends() -> None:
    job = Job(turns_per_layer=3, layers=3, poles=3)
    pos = list(job.segments()[0].start)
    for seg in job.segments():
        path = interpolate(pos, seg.delta)
        assert path.shape[0] == seg.steps
        pos = path[-1].tolist()
    assert tuple(pos) == job.segments()[-1].end


BAD = [
    ("wire_diameter", -1.0, "must be in (0, 0.02] m"),
    ("wire_diameter", 0.0, "must be in (0, 0.02] m"),
    ("wire_diameter", math.nan, "must be a finite number"),
    ("wire_diameter", math.inf, "must be a finite number"),
    ("wire_diameter", "thick", "must be a number"),
    ("flyer_radius", 1e9, "must be in (0, 5] m"),
    ("turns_per_layer", 0, "must be in [1, 100000]"),
    ("turns_per_layer", 2.5, "must be an integer"),
    ("turns_per_layer", True, "must be an integer"),
    ("layers", -3, "must be in [1, 1000]"),
    ("poles", 10**9, "must be in [1, 360]"),
    ("fork_steps_per_rev", 3, "must be in [4, 16777216]"),
    ("feed_step", 0.0, "must be in (0, 0.001] m"),
    ("pole_steps_per_rev", None, "must be an integer"),
    ("coil_length", -0.1, "must be in [0, 10] m"),
    ("job_id", "my job!", "must be 1-64 letters"),
    ("job_id", "", "must be 1-64 letters"),
]


@pytest.mark.parametrize(("name", "value", "why"), BAD)
def test_bad_field_is_rejected_with_name_value_and_range(name: str, value: object, why: str) -> None:
    with pytest.raises(JobError) as info:
        Job(**{name: value})
    msg = str(info.value)
    assert msg.startswith(f"{name}=")
    assert "is invalid" in msg
    assert why in msg
    assert "\n" not in msg


def test_cross_field_checks() -> None:
    with pytest.raises(JobError, match=r"feed_step=0.0005 m is invalid for wire_diameter=0.0001 m"):
        Job(wire_diameter=1e-4, feed_step=5e-4)
    with pytest.raises(
        JobError, match=r"^layer 1 needs 20 turns x 2\.5 mm = 50\.0 mm, .* \(at most 4 turns fit\)$"
    ):
        Job(coil_length=0.0101)  # the deprecated name of bobbin.window_width
    with pytest.raises(JobError, match="unknown job field 'speed'"):
        Job.from_dict({"speed": 3})
    assert Job.from_dict(Job().to_dict()) == Job()


def test_every_field_has_a_spec() -> None:
    assert set(Job().to_dict()) == set(FIELD_SPECS)


def run_cli(*args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, "-m", "winder.cli", *args],
        capture_output=True,
        text=True,
        timeout=120,
        stdin=subprocess.DEVNULL,
    )


def test_cli_interp_prints_summary() -> None:
    r = run_cli("interp", "--turns-per-layer", "4", "--poles", "2")
    assert r.returncode == 0, r.stderr
    assert "steps              " in r.stdout
    job = Job(turns_per_layer=4, poles=2)
    assert f"steps              {job.total_steps} " in r.stdout
    end = job.segments()[-1].end
    assert f"feed {end[0]}  fork {end[1]}  pole {end[2]} steps" in r.stdout


@pytest.mark.parametrize(
    ("args", "expect"),
    [
        (["--poles", "0"], "poles=0 is invalid: must be in [1, 360]"),
        (["--wire-diameter", "abc"], "wire_diameter='abc' is invalid: must be a number"),
        (["--turns-per-layer", "1e99"], "turns_per_layer='1e99' is invalid: must be an integer"),
        (["--feed-step", "nan"], "feed_step=nan is invalid: must be a finite number"),
        (["--job-id", "a/b"], "job_id='a/b' is invalid"),
    ],
)
def test_cli_bad_input_is_one_line_without_traceback(args: list[str], expect: str) -> None:
    r = run_cli("interp", *args)
    assert r.returncode == 2
    assert "Traceback" not in r.stderr
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1, r.stderr
    assert expect in lines[0]


@settings(max_examples=80, deadline=None)
@given(st.data())
def test_coil_overrides_wind_each_coil_as_given(data: st.DataObject) -> None:
    """Segments of a job with random per-coil overrides against a walk written
    here: each coil its own turns, layers and fork direction, the feed
    reversing at every layer, the pole indexing between coils."""
    poles = data.draw(st.integers(1, 6))
    tpl, layers = data.draw(st.integers(1, 8)), data.draw(st.integers(1, 3))
    spr = data.draw(st.sampled_from([4, 16, 1024]))
    over: dict[int, dict[str, object]] = {}
    for coil in range(1, poles + 1):
        keys = data.draw(
            st.dictionaries(st.sampled_from(["turns_per_layer", "layers", "direction"]), st.just(0))
        )
        values = {
            k: data.draw(st.integers(1, 8) if k != "direction" else st.sampled_from(["cw", "ccw"]))
            for k in keys
        }
        if values:
            over[coil] = values
    text = ";".join(f"{c}:" + ",".join(f"{k}={v}" for k, v in kv.items()) for c, kv in over.items())
    job = Job(poles=poles, turns_per_layer=tpl, layers=layers, fork_steps_per_rev=spr, coil_overrides=text)
    want = []
    pos, feed_dir = [0, 0, 0], 1
    for pole in range(poles):
        if pole:
            step = round(pole * 1024 / poles) - round((pole - 1) * 1024 / poles)
            want.append((tuple(pos), (0, 0, step)))
            pos[2] += step
        kv = over.get(pole + 1, {})
        turns = int(kv.get("turns_per_layer", tpl))  # type: ignore[call-overload]
        sign = -1 if kv.get("direction") == "ccw" else 1
        for _ in range(int(kv.get("layers", layers))):  # type: ignore[call-overload]
            delta = (feed_dir * turns * 250, sign * turns * spr, 0)  # 2.5 mm wire / 10 um feed steps
            want.append((tuple(pos), delta))
            pos = [p + d for p, d in zip(pos, delta, strict=True)]
            feed_dir = -feed_dir
    assert [(s.start, s.delta) for s in job.segments()] == want
    assert Job.from_dict(job.to_dict()) == job  # travels in the job description as it is
    end = np.asarray(job.segments()[0].start)
    for s in job.segments():
        end = interpolate(end, s.delta)[-1]
    assert tuple(end) == tuple(pos)


@pytest.mark.parametrize(
    ("text", "why"),
    [
        ("5:layers=1", r"coil 5 is not in \[1, 4\]"),
        ("2:turns=3", "unknown key 'turns'"),
        ("2:direction=up", "must be cw or ccw"),
        ("2:layers=0", r"layers=0 is invalid: must be .*\[1, 1000\]"),
        ("1:layers=1;1:layers=2", "coil 1 is given twice"),
        ("x", "COIL:KEY=VALUE"),
    ],
)
def test_bad_coil_overrides_are_refused_in_one_line(text: str, why: str) -> None:
    with pytest.raises(JobError, match=why) as err:
        Job(coil_overrides=text)
    assert "\n" not in str(err.value) and "coil_overrides" in str(err.value)


def test_a_coil_override_is_checked_like_the_job() -> None:
    with pytest.raises(JobError, match=r"^coil 3: layer 1 needs 30 turns x 2\.5 mm = 75\.0 mm"):
        Job(coil_length=0.05, coil_overrides="3:turns_per_layer=30")


def test_programmed_stops_count_a_coils_own_turns() -> None:
    from winder.contract.params import stop_place, stop_points

    job = Job(poles=3, turns_per_layer=4, layers=2, coil_overrides="2:turns_per_layer=6,direction=ccw")
    segs = job.segments()
    # coil 2, turn 9: its second layer (6 turns each), 3 turns in
    [(seg, k)] = stop_points(job, "2:9")
    assert (segs[seg].pole, segs[seg].layer, k) == (1, 1, 3 * 1024)
    assert stop_place(job, segs[seg], k) == (2, 2, 9)
    with pytest.raises(SpecError, match=r"turn 13 of coil 2 is not in \[1, 12\]"):
        stop_points(job, "2:13")
