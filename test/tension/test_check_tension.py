"""`winder check`'s wire: the `wire` object, each layer's predicted tension,
and a job whose wire would not hold refused in one line (exit 2) that names
the layer, the prediction, the limit and the flyer speed that keeps it."""

from __future__ import annotations

import json
import math
import re
import subprocess
from pathlib import Path

import pytest
from support.paths import ROOT

from winder.motion.material import MATERIALS

WINDER = ROOT / ".venv" / "bin" / "winder"
RECT = ROOT / "jobs" / "ortho_rect.yaml"


def check(path: Path, *args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [str(WINDER), "check", str(path), *args], capture_output=True, text=True, timeout=120
    )


def with_consumer(tmp_path: Path, line: str) -> Path:
    """ortho_rect.yaml with one more setting in its sim_node section."""
    text = RECT.read_text().replace(
        "sim_node:\n  ros__parameters:\n", f"sim_node:\n  ros__parameters:\n    {line}\n", 1
    )
    out = tmp_path / "job.yaml"
    out.write_text(text)
    return out


def test_the_wire_and_each_layers_tension_are_reported() -> None:
    out = check(RECT, "--json")
    assert out.returncode == 0, out.stderr
    doc = json.loads(out.stdout)
    wire = doc["wire"]
    bare = 0.00045
    assert wire["yield_stress_pa"] == 68.9e6 and wire["material"] == "copper"
    assert math.isclose(wire["max_tension_n"], 68.9e6 * math.pi * bare**2 / 4, rel_tol=1e-12)
    assert math.isclose(wire["set_tension_n"], wire["max_tension_n"] / 2, rel_tol=1e-12)
    assert wire["tensioner"] == "dancer"
    for layer in doc["layers"]:
        assert layer["takeup_ratio"] > 1
        assert (
            wire["alarm_band_n"][0]
            < layer["tension_min_n"]
            <= layer["tension_peak_n"]
            < wire["alarm_band_n"][1]
        )
    text = check(RECT).stdout
    assert "wire           copper, max tension 10.96 N (yield 68.9 MPa x bare section 0.159 mm2)" in text


def test_a_tensioner_that_cannot_follow_the_corners_is_refused_in_one_line(tmp_path: Path) -> None:
    job = with_consumer(tmp_path, "tensioner.kind: servo")
    out = check(job)
    assert out.returncode == 2
    lines = out.stderr.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in out.stderr, out.stderr
    m = re.fullmatch(
        r"winder check: error: layer 1 at ([\d.]+) rad/s: predicted peak tension ([\d.]+) N passes the "
        r"wire's maximum ([\d.]+) N \(yield 68\.9 MPa x bare section 0\.159 mm2\); the highest flyer "
        r"speed at which its steady swing keeps it is ([\d.]+) rad/s, \d+% of it \(servo tensioner\)",
        lines[0],
    )
    assert m, lines[0]
    speed, peak, limit, keep = map(float, m.groups())
    assert peak > limit and 0 < keep < speed
    assert "fits           NO: layer 1" in out.stdout  # the report stands on stdout
    doc = json.loads(check(job, "--json").stdout)
    words = lines[0].removeprefix("winder check: error: ")
    assert doc["fits"] is False and doc["overflow"] == words
    # the same tensioner given as an option instead of in the job file: the same words
    assert check(RECT, "--tensioner.kind", "servo").stderr == out.stderr
    # winder run refuses it in the same words, before anything starts
    for argv in (["run", "--check", str(job)], ["run", str(job)]):
        out = subprocess.run([str(WINDER), *argv], capture_output=True, text=True, timeout=60)
        assert out.returncode == 2 and out.stdout == "", out.stdout + out.stderr
        assert out.stderr == f"winder run: error: {words}\n"


def test_a_set_tension_beyond_the_wire_is_refused() -> None:
    out = check(RECT, "--tension.set", "11")
    assert out.returncode == 2
    assert out.stderr.strip() == (
        "winder check: error: tension.set=11 N is invalid: must be at most the wire's maximum 10.96 N "
        "(yield 68.9 MPa x bare section 0.159 mm2)"
    )


@pytest.mark.parametrize("material", ["copper", "aluminium"])
def test_the_material_sets_the_resistance_and_the_maximum(material: str) -> None:
    out = check(RECT, "--json", "--wire.material", material, "--tension.set", "1")
    doc = json.loads(out.stdout)
    m = MATERIALS[material]
    section = math.pi * 0.00045**2 / 4
    assert math.isclose(doc["resistance_ohm"], m.resistivity * doc["wire_length_m"] / section, rel_tol=1e-12)
    assert math.isclose(doc["wire"]["max_tension_n"], m.yield_stress * section, rel_tol=1e-12)


@pytest.mark.parametrize(
    ("setting", "words"),
    [
        (
            "tensioner.dancer_damping: 0.1",
            r"the dancer would oscillate \(440 Hz, growing at [\d.]+ 1/s\) with "
            r"tensioner\.dancer_damping 0\.1 N s/m and tensioner\.supply_gain 20 1/s on a span of "
            r"3\.817e\+04 N/m: raise the damping or lower the supply gain",
        ),
        (
            "tensioner.supply_gain: 1000",
            r"the dancer would oscillate \(441 Hz.*tensioner\.supply_gain 1000 1/s",
        ),
        (
            "tensioner.kind: servo\n    tensioner.force_limit: 1",
            r"tensioner\.force_limit 1 N is below the set tension 5\.479 N: the servo cannot hold it",
        ),
    ],
    ids=["low damping", "high supply gain", "weak servo"],
)
def test_a_tensioner_that_cannot_work_is_refused_in_one_line(
    tmp_path: Path, setting: str, words: str
) -> None:
    """A dancer whose linear system has a pole in the right half-plane (checked
    here against a long simulation of it growing) and a servo weaker than the
    set tension: refused before any prediction, in one line, exit 2."""
    job = with_consumer(tmp_path, setting)
    for argv in (["check", str(job)], ["run", "--check", str(job)]):
        out = subprocess.run([str(WINDER), *argv], capture_output=True, text=True, timeout=60)
        assert out.returncode == 2, out.stdout + out.stderr
        line = out.stderr.strip()
        assert "\n" not in line and "Traceback" not in out.stderr
        assert re.fullmatch(rf"winder (check|run): error: {words}.*", line), line


def test_unstable_is_what_a_simulation_shows() -> None:
    """Tensioner.unstable against the system itself: an impulse in the span dies
    out or grows over a long run (scipy's lsim), as it says."""
    import numpy as np
    import scipy.signal

    from winder.tension.tensioner import Tensioner

    for damping, gain in ((1.0, 20.0), (0.1, 20.0), (1.0, 200.0), (5.0, 100.0)):
        t = Tensioner("dancer", 38170.0, 5.0, damping=damping, supply_gain=gain)
        a, b, c, d = t.matrices()
        time = np.linspace(0.0, 4.0, 40001)
        _, y, _ = scipy.signal.lsim(
            (a, b[:, None], c, d[:, None]), np.zeros(time.size), time, X0=[1e-6, 0, 0, 0]
        )
        grows = np.abs(y[-4000:, 0]).max() > np.abs(y[:4000, 0]).max()
        assert bool(t.unstable()) == grows, (damping, gain, t.unstable())


@pytest.mark.parametrize(
    ("args", "words"),
    [
        (
            ["--tension.warning", "0.5", "--tension.alarm", "0.2"],
            "tension.warning=0.5 is invalid: must be at most tension.alarm=0.2 (the warning band lies inside "
            "the alarm band)",
        ),
        (
            ["--bobbin.core", "rect", "--bobbin.core-corner-radius", "0.003"],
            "bobbin.core_corner_radius=0.003 m is invalid without the core's size: give "
            "bobbin.core_width and bobbin.core_depth",
        ),
    ],
)
def test_bands_and_corners_that_make_no_sense_are_refused(args: list[str], words: str) -> None:
    out = subprocess.run([str(WINDER), "check", *args], capture_output=True, text=True, timeout=60)
    assert out.returncode == 2 and out.stderr == f"winder check: error: {words}\n", out.stderr


def test_a_smaller_max_share_lowers_the_default_set_tension() -> None:
    doc = json.loads(check(RECT, "--json", "--tension.max-share", "0.3").stdout)
    wire = doc["wire"]
    assert math.isclose(wire["set_tension_n"], wire["max_tension_n"] * 0.3 / 2, rel_tol=1e-12)
