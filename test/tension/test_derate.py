"""tension.derate: layers slowed in time until their predicted tension keeps
within the bounds. A layer's pace s is an exact time scaling of its move
(checked against the unscaled move, sampled at s t); the layer_speed key is
refused in one line where it makes no sense; winder check derates a job it
would otherwise refuse, and a derated run's recorded tension stays within the
alarm band worked out here from the wire's published figures."""

from __future__ import annotations

import json
import math
import subprocess
from pathlib import Path

import numpy as np
import pytest
from conftest import Procs
from hypothesis import given, settings
from hypothesis import strategies as st
from support.cell import only_bag, winder_run
from support.paths import BIN

from winder.contract.params import PROFILE_SPECS
from winder.motion.job import Job, JobError
from winder.motion.timing import plan_segment
from winder.record.reader import read_run

WINDER = BIN / "winder"
RECT = Path(__file__).resolve().parents[2] / "jobs" / "ortho_rect.yaml"
#: a servo tensioner at its defaults cannot follow this job's ramps at full speed
SERVO = ["--tensioner.kind", "servo", "--turns-per-layer", "12", "--layers", "2"]


@settings(max_examples=60, deadline=None)
@given(
    kind=st.sampled_from(["trapezoid", "scurve", "exponential"]),
    steps=st.integers(50, 200_000),
    pace=st.floats(0.05, 1.0),
    v_max=st.floats(500.0, 50_000.0),
)
def test_a_layers_pace_is_an_exact_time_scaling_of_its_move(
    kind: str, steps: int, pace: float, v_max: float
) -> None:
    values = {n: s.default for n, s in PROFILE_SPECS.items()} | {"profile": kind, "v_max": v_max}
    values |= {"a_max": v_max * 8, "j_max": v_max * 200, "tau": 0.05}
    fast = plan_segment(values, steps)
    slow = plan_segment(values, steps, speed=pace, pace=pace)
    assert math.isclose(slow.duration, fast.duration / pace, rel_tol=1e-9)
    t = np.linspace(0.0, slow.duration, 257)
    p_slow = slow.sample(t)[0]
    p_fast = fast.sample(t * pace)[0]
    assert np.allclose(p_slow, p_fast, rtol=0, atol=1e-6 * steps)


def test_layer_speed_slows_the_layers_it_names() -> None:
    job = Job.from_dict({"layer_speed": "*:2=0.8;1:1=0.5", "first_layer_speed": 0.5, "layers": 2})
    got = {
        (s.pole, s.layer): (job.segment_speed(s), job.segment_pace(s)) for s in job.segments() if s.kind.winds
    }
    for (pole, layer), (speed, pace) in got.items():
        want_pace = 0.8 if layer == 1 else (0.5 if pole == 0 else 1.0)
        assert pace == want_pace
        assert speed == (0.5 if layer == 0 else 1.0) * want_pace


@pytest.mark.parametrize(
    ("text", "words"),
    [
        ("9:1=0.5", "layer_speed: coil 9 is not in [1, 4] (poles)"),
        ("1:3=0.5", "layer_speed: '1:3=0.5': layer 3 is not in [1, 2] (the layers of coil 1)"),
        ("1:1=1.5", "layer_speed: '1:1=1.5': share 1.5 is invalid: must be in [0.001, 1]"),
        ("1-1=0.5", "layer_speed: '1-1=0.5' must be COIL:LAYER=SHARE (COIL a number or *)"),
    ],
)
def test_a_layer_speed_that_makes_no_sense_is_refused_in_one_line(text: str, words: str) -> None:
    with pytest.raises(JobError) as err:
        Job.from_dict({"layer_speed": text, "layers": 2})
    assert str(err.value) == words


def check(*args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [str(WINDER), "check", str(RECT), *args], capture_output=True, text=True, timeout=120
    )


def alarm_band() -> tuple[float, float]:
    """The job's alarm band from the published figures: copper's 68.9 MPa
    over the 0.45 mm bare section, set at half of it, +-40 %."""
    top = 68.9e6 * math.pi * 0.00045**2 / 4
    return top / 2 * 0.6, top / 2 * 1.4


def test_check_derates_a_job_it_would_refuse() -> None:
    refused = check(*SERVO)
    assert refused.returncode == 2 and "predicted peak tension" in refused.stderr, refused.stderr
    out = check(*SERVO, "--tension.derate", "--json")
    assert out.returncode == 0, out.stderr
    doc = json.loads(out.stdout)
    low, high = alarm_band()
    derated = doc["wire"]["derated"]
    assert derated["duration_after_s"] > derated["duration_before_s"]
    assert {(x["coil"], x["layer"]) for x in derated["layers"]} == {(1, 1), (1, 2)}
    assert all(0 < x["speed_share"] < 1 for x in derated["layers"])
    for layer in doc["layers"]:
        assert low <= layer["tension_min_n"] <= layer["tension_peak_n"] <= high
    text = check(*SERVO, "--tension.derate").stdout
    assert "  derated        2 layers slowed to " in text and "fits           yes" in text


@pytest.mark.ros
def test_a_derated_run_keeps_its_tension_within_the_alarm_band(tmp_path: Path, procs: Procs) -> None:
    r = winder_run(tmp_path, procs.domain, str(RECT), *SERVO, "--tension.derate")
    assert r.returncode == 0, r.stdout + r.stderr
    assert "tension.derate: 2 layers slowed to" in r.stdout
    assert "  derated            2 layers slowed to" in r.stdout  # and again in the summary
    run = read_run(only_bag(tmp_path))
    low, high = alarm_band()
    tension = run.tension.tension
    assert tension.size > 1000
    assert low <= float(tension.min()) and float(tension.max()) <= high
