"""The coil as laid in its bobbin, the fit check, and the job file's hash in the run.

The geometry rules are written again here, from docs/OPERATING.md (Coil
geometry), and the job's layout (winder.motion.coil through Job) and ``winder check`` (text and
--json, on every shipped job) are compared with them; hypothesis draws the
geometry, including windows that are an exact multiple of the wire. A job
that does not fit is refused in the same one line by ``winder check``,
``winder run --check`` and a real interp node (at start and on ~/start_run);
a run started from a job file carries the file's sha256 into its bag.
"""

from __future__ import annotations

import hashlib
import json
import math
import re
import subprocess
import sys
from fractions import Fraction
from pathlib import Path
from typing import Any

import pytest
from conftest import Procs
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from ruamel.yaml import YAML
from support import wait
from support.bags import finished_run
from support.paths import ROOT

from winder.motion.job import Job, JobError

JOBS = sorted((ROOT / "jobs").glob("*.yaml"))
WINDER = Path(sys.executable).with_name("winder")

# -- the rules, written again ---------------------------------------------------------------
RHO = 1.7241e-8  # ohm m, annealed copper at 20 C
TOL = Fraction(1, 10**9)  # a layer whose turns stick out by at most 1 nm fits (documented)


def turns_of_layers(w: float, d: float, lay: str, layers: int, asked: int | None) -> list[int]:
    """Turns of each layer: the asked number, or as many as fit (auto)."""
    if asked is not None:
        return [asked] * layers
    wf, df = Fraction(w) + TOL, Fraction(d)
    n1 = math.floor(wf / df)
    out = []
    for layer in range(1, layers + 1):
        if lay == "helical" or layer % 2 == 1:
            out.append(n1)
        else:  # in the grooves, shifted by d/2: n1 when W - n1 d >= d/2
            out.append(n1 if wf - n1 * df >= df / 2 else max(n1 - 1, 0))
    return out


def layer_fits(w: float, d: float, lay: str, layer: int, turns: int) -> bool:
    if w == 0:
        return True
    shift = Fraction(d) / 2 if lay == "orthocyclic" and layer % 2 == 0 else Fraction(0)
    return turns >= 1 and turns * Fraction(d) + shift <= Fraction(w) + TOL


def pitch(d: float, lay: str) -> float:
    return d * math.sqrt(3) / 2 if lay == "orthocyclic" else d


def turn_length(core: dict[str, float], d: float, lay: str, layer: int) -> float:
    r = d / 2 + (layer - 1) * pitch(d, lay)
    if "diameter" in core:
        return math.pi * (core["diameter"] + 2 * r)
    # the layer's centre line: four flats, each shortened by its two corners' radius
    # (the core's corner radius + r), and four quarter circles of that radius
    corner = core.get("corner", 0.0) + r
    a, b = core["width"] + 2 * r, core["depth"] + 2 * r
    return 2 * (a - 2 * corner) + 2 * (b - 2 * corner) + 4 * (math.pi / 2) * corner


def expected(
    w: float,
    h: float,
    d: float,
    d_bare: float,
    lay: str,
    core: dict[str, float] | None,
    coils: list[tuple[int | None, int]],
) -> dict[str, Any]:
    """What the rules say of a job whose coils are (turns per layer or None, layers)."""
    per_coil = []
    for asked, layers in coils:
        turns = turns_of_layers(w, d, lay, layers, asked)
        lengths = [turn_length(core, d, lay, i + 1) for i in range(layers)] if core else None
        height = d + (layers - 1) * pitch(d, lay)
        fits = all(layer_fits(w, d, lay, i + 1, t) for i, t in enumerate(turns)) and (
            h == 0 or height <= h + 1e-9
        )
        area = math.pi * d_bare**2 / 4
        per_coil.append(
            {
                "turns": turns,
                "turn_length_m": lengths,
                "radius_m": [d / 2 + i * pitch(d, lay) for i in range(layers)],
                "total_turns": sum(turns),
                "build_height_m": height,
                "wire_length_m": sum(t * x for t, x in zip(turns, lengths, strict=True)) if lengths else None,
                "fill_factor": sum(turns) * area / (w * h) if w > 0 and h > 0 else None,
                "finish_side": "start" if layers % 2 == 0 else "far",
                "fits": fits,
            }
        )
    wire = None if core is None else sum(c["wire_length_m"] for c in per_coil)
    return {
        "coils": per_coil,
        "total_turns": sum(c["total_turns"] for c in per_coil),
        "wire_length_m": wire,
        "resistance_ohm": None if wire is None else RHO * wire / (math.pi * d_bare**2 / 4),
        "fits": all(c["fits"] for c in per_coil),
    }


def approx(x: float | None) -> Any:
    return None if x is None else pytest.approx(x, rel=1e-12, abs=1e-15)


def check_layout(job: Job, want: dict[str, Any]) -> None:
    laid = job.winding
    assert laid.fits == want["fits"], laid.overflow()
    assert laid.total_turns == want["total_turns"]
    assert laid.wire_length == approx(want["wire_length_m"])
    assert laid.resistance == approx(want["resistance_ohm"])
    for coil, w in zip(laid.coils, want["coils"], strict=True):
        assert [layer.turns for layer in coil.layers] == w["turns"]
        assert [layer.radius for layer in coil.layers] == [approx(r) for r in w["radius_m"]]
        if w["turn_length_m"] is None:
            assert all(layer.turn_length is None for layer in coil.layers)
        else:
            assert [layer.turn_length for layer in coil.layers] == [approx(x) for x in w["turn_length_m"]]
        assert coil.build_height == approx(w["build_height_m"])
        assert coil.fill_factor == approx(w["fill_factor"])
        assert coil.finish_side == w["finish_side"]
        assert coil.fits == w["fits"]
        assert (coil.overflow() == "") == w["fits"]


# -- hypothesis over random geometry ----------------------------------------------------------
# lengths in whole micrometres, as a drawing gives them, and as floats of any value
MICRONS = st.integers(50, 3000).map(lambda k: k / 1e6)
LAYS = st.sampled_from(["helical", "orthocyclic"])


@st.composite
def geometry(draw: st.DrawFn) -> dict[str, Any]:
    d = draw(st.one_of(MICRONS, st.floats(5e-5, 3e-3)))
    lay = draw(LAYS)
    n = draw(st.integers(1, 300))
    kind = draw(st.sampled_from(["exact", "exact_decimal", "half", "short", "long", "any"]))
    w = {
        "exact": n * d,  # W = n d in floating point: must hold n
        "exact_decimal": float(Fraction(round(d * 1e6)) * n / 10**6) if d * 1e6 == round(d * 1e6) else n * d,
        "half": (n + 0.5) * d,  # orthocyclic: every layer holds n
        "short": n * d - 2e-9,  # 2 nm short: n - 1
        "long": n * d + 2e-9,
        "any": draw(st.floats(d, 0.2)),
    }[kind]
    layers = draw(st.integers(1, 40))
    asked = draw(st.one_of(st.none(), st.integers(1, 400)))
    h = draw(st.one_of(st.just(0.0), st.floats(d, 0.05), st.just(d + (layers - 1) * pitch(d, lay))))
    core = draw(
        st.one_of(
            st.none(),
            st.builds(lambda x: {"diameter": x}, st.floats(1e-3, 0.2)),
            st.builds(lambda a, b: {"width": a, "depth": b}, st.floats(1e-3, 0.2), st.floats(1e-3, 0.2)),
        )
    )
    bare = draw(st.floats(0.5, 1.0)) * d
    return {"d": d, "lay": lay, "w": w, "h": h, "layers": layers, "asked": asked, "core": core, "bare": bare}


def job_of(g: dict[str, Any], check_fit: bool = False, **extra: Any) -> Job:
    values: dict[str, Any] = {
        "wire_diameter": g["d"],
        "wire.bare_diameter": g["bare"],
        "feed_step": g["d"] / 8,
        "fork_steps_per_rev": 16,
        # 8 fork steps: the feed's 8 steps of a linear crossover never outrun the flyer (the layout's
        # the subject here, not the cam law: tests/motion/test_orthocyclic.py)
        "lay.crossover": 180.0,
        "lay.crossover_law": "linear",
        "flyer_radius": 1.0,
        "poles": 1,
        "lay": g["lay"],
        "layers": g["layers"],
        "turns_per_layer": "auto" if g["asked"] is None else g["asked"],
        "bobbin.window_width": g["w"],
        "bobbin.window_height": g["h"],
        **extra,
    }
    core = g["core"]
    if core and "diameter" in core:
        values.update({"bobbin.core": "round", "bobbin.core_diameter": core["diameter"]})
    elif core:
        values.update(
            {"bobbin.core": "rect", "bobbin.core_width": core["width"], "bobbin.core_depth": core["depth"]}
        )
    return Job.from_dict(values, check_fit=check_fit)


@settings(max_examples=400, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(geometry())
def test_the_layout_is_the_rules(g: dict[str, Any]) -> None:
    job = job_of(g)
    want = expected(g["w"], g["h"], g["d"], g["bare"], g["lay"], g["core"], [(g["asked"], g["layers"])])
    check_layout(job, want)
    if want["fits"]:
        assert job_of(g, check_fit=True) == job
    else:
        with pytest.raises(JobError) as err:
            job_of(g, check_fit=True)
        assert str(err.value) == job.winding.overflow() and "\n" not in str(err.value)


@settings(max_examples=200, deadline=None)
@given(MICRONS, st.integers(1, 400), LAYS)
def test_a_window_of_exactly_n_wires_holds_n(d: float, n: int, lay: str) -> None:
    """W = n d (as the float product, and as the decimal typed) holds n turns
    in layer 1; 2 nm less holds n - 1; an orthocyclic even layer holds n only
    from W = (n + 1/2) d."""
    decimal = float(Fraction(round(d * 1e6) * n, 10**6))
    for w in (n * d, decimal):
        g = {"d": d, "lay": lay, "w": w, "h": 0.0, "layers": 2, "asked": None, "core": None, "bare": d}
        turns = [layer.turns for layer in job_of(g).winding.coils[0].layers]
        assert turns == [n, n if lay == "helical" else n - 1]
        assert job_of({**g, "asked": n, "layers": 1}, check_fit=True).layer_turns == n
    g = {"d": d, "lay": lay, "w": n * d - 2e-9, "h": 0.0, "layers": 1, "asked": None, "core": None, "bare": d}
    assert job_of(g).winding.coils[0].layers[0].turns == n - 1
    g = {
        "d": d,
        "lay": lay,
        "w": (n + 0.5) * d,
        "h": 0.0,
        "layers": 2,
        "asked": None,
        "core": None,
        "bare": d,
    }
    assert [layer.turns for layer in job_of(g).winding.coils[0].layers] == [n, n]


def test_coil_overrides_are_laid_coil_by_coil() -> None:
    g = {"d": 5e-4, "lay": "helical", "w": 0.014, "h": 0.003, "layers": 3, "asked": 24, "bare": 4.5e-4}
    g["core"] = {"width": 0.004, "depth": 0.012}
    job = job_of(g, poles=4, coil_overrides="2:layers=2;4:turns_per_layer=20")
    coils = [(24, 3), (24, 2), (24, 3), (20, 3)]
    check_layout(job, expected(0.014, 0.003, 5e-4, 4.5e-4, "helical", g["core"], coils))
    with pytest.raises(JobError, match=r"^coil 2: layer 1 needs 30 turns x 0\.5 mm = 15\.0 mm, "):
        job_of(g, check_fit=True, poles=2, coil_overrides="2:turns_per_layer=30")


@pytest.mark.parametrize(
    ("values", "words"),
    [
        (
            {"bobbin.window_width": 0.048},
            "layer 1 needs 20 turns x 2.5 mm = 50.0 mm, the window is 48.0 mm wide: 2.0 mm over "
            "(at most 19 turns fit)",
        ),
        (
            {"bobbin.window_width": 0.05, "lay": "orthocyclic"},
            "layer 2 needs 20 turns x 2.5 mm + 1.25 mm offset = 51.25 mm, the window is 50.0 mm wide: "
            "1.25 mm over (at most 19 turns fit)",
        ),
        (
            {"bobbin.window_height": 0.004},
            "2 layers of 2.5 mm wire build 5.0 mm (helical, radial pitch 2.5 mm), the window is 4.0 mm "
            "high: 1.0 mm over (at most 1 layers fit)",
        ),
        (
            {"bobbin.window_width": 0.002, "turns_per_layer": "auto"},
            "layer 1 needs 1 turn x 2.5 mm = 2.5 mm, the window is 2.0 mm wide: 0.5 mm over (no turn fits)",
        ),
    ],
)
def test_what_overflows_and_by_how_much(values: dict[str, Any], words: str) -> None:
    with pytest.raises(JobError) as err:
        Job.from_dict(values)
    assert str(err.value) == words


@pytest.mark.parametrize(
    ("values", "why"),
    [
        ({"turns_per_layer": "auto"}, "turns_per_layer=auto is invalid without bobbin.window_width"),
        (
            {"turns_per_layer": "many"},
            "turns_per_layer='many' is invalid: must be an integer in [1, 100000] or auto",
        ),
        ({"lay": "random"}, "lay='random' is invalid: must be one of helical, orthocyclic"),
        ({"bobbin.core": "oval"}, "bobbin.core='oval' is invalid: must be one of round, rect"),
        ({"bobbin.core": "rect", "bobbin.core_width": 0.01}, "give both"),
        ({"bobbin.core_width": 0.01}, "bobbin.core=round is invalid with bobbin.core_width"),
        ({"bobbin.core": "rect", "bobbin.core_diameter": 0.01}, "bobbin.core=rect is invalid with"),
        (
            {"wire.bare_diameter": 0.003},
            "wire.bare_diameter=0.003 m is invalid: must be at most wire_diameter",
        ),
        ({"lay.crossover": 0.0}, "lay.crossover=0.0 is invalid: must be in (0, 360] deg"),
        ({"lay.crossover_at": 360.0}, "lay.crossover_at=360 is invalid: must be in [0, 360) deg"),
        ({"reversal_dwell": -1.0}, "reversal_dwell=-1.0 is invalid: must be in [0, 1000] turns"),
        ({"first_layer_speed": 0.0}, "first_layer_speed=0.0 is invalid: must be in [0.001, 1]"),
        ({"first_layer_speed": 1.5}, "first_layer_speed=1.5 is invalid: must be in [0.001, 1]"),
        ({"coil_length": 0.05, "bobbin.window_width": 0.06}, "coil_length is the deprecated name"),
    ],
)
def test_geometry_settings_are_checked_in_one_line(values: dict[str, Any], why: str) -> None:
    with pytest.raises(JobError) as err:
        Job.from_dict(values)
    assert why in str(err.value) and "\n" not in str(err.value)


def test_coil_length_is_the_window_width_still() -> None:
    assert Job(coil_length=0.05).winding == Job.from_dict({"bobbin.window_width": 0.05}).winding
    assert Job.from_dict({"coil_length": 0.05, "bobbin.window_width": 0.05}).layer_turns == 20


# -- winder check on every shipped job -------------------------------------------------------


def flat(doc: Any) -> dict[str, Any]:
    out: dict[str, Any] = {}
    stack = [("", doc["interp_node"]["ros__parameters"])]
    while stack:
        prefix, d = stack.pop()
        for k, v in d.items():
            name = f"{prefix}.{k}" if prefix else k
            if isinstance(v, dict):
                stack.append((name, v))
            else:
                out[name] = v
    return out


def expected_of_file(path: Path) -> dict[str, Any]:
    """The rules applied to a job file's values, read here (defaults as documented)."""
    v = flat(YAML(typ="safe").load(path.read_text()))
    d = v["wire_diameter"]
    w = v.get("bobbin.window_width", v.get("coil_length", 0.0))
    core: dict[str, float] | None = None
    if v.get("bobbin.core", "round") == "round" and v.get("bobbin.core_diameter", 0):
        core = {"diameter": v["bobbin.core_diameter"]}
    elif v.get("bobbin.core") == "rect" and v.get("bobbin.core_width", 0):
        core = {
            "width": v["bobbin.core_width"],
            "depth": v["bobbin.core_depth"],
            "corner": v.get("bobbin.core_corner_radius", 0.0),
        }
    asked = None if v.get("turns_per_layer", 20) == "auto" else v.get("turns_per_layer", 20)
    coils = [(asked, v.get("layers", 2)) for _ in range(v.get("poles", 4))]
    for item in filter(None, (t.strip() for t in v.get("coil_overrides", "").split(";"))):
        number, _, body = item.partition(":")
        for pair in body.split(","):
            key, _, value = pair.partition("=")
            t, n = coils[int(number) - 1]
            if key.strip() == "layers":
                coils[int(number) - 1] = (t, int(value))
            elif key.strip() == "turns_per_layer":
                coils[int(number) - 1] = (int(value), n)
    bare = v.get("wire.bare_diameter", 0.0) or d
    want = expected(w, v.get("bobbin.window_height", 0.0), d, bare, v.get("lay", "helical"), core, coils)
    want["job_id"] = v["job_id"]
    return want


def test_the_shipped_jobs_include_two_orthocyclic_recipes_that_fit() -> None:
    lays = {p.stem: flat(YAML(typ="safe").load(p.read_text())) for p in JOBS}
    ortho = {k: v for k, v in lays.items() if v.get("lay") == "orthocyclic"}
    assert {v.get("bobbin.core") for v in ortho.values()} == {"round", "rect"}
    assert all(expected_of_file(ROOT / "jobs" / f"{k}.yaml")["fits"] for k in ortho)


@pytest.mark.parametrize("path", JOBS, ids=[p.stem for p in JOBS])
def test_winder_check_agrees_with_the_rules(path: Path) -> None:
    want = expected_of_file(path)
    out = subprocess.run(
        [str(WINDER), "check", str(path), "--json"], capture_output=True, text=True, timeout=60
    )
    assert out.returncode == (0 if want["fits"] else 2), out.stderr
    doc = json.loads(out.stdout)
    first = want["coils"][0]
    assert doc["job_id"] == want["job_id"]
    assert [x["turns"] for x in doc["layers"]] == first["turns"]
    lengths = [x["turn_length_m"] for x in doc["layers"]]
    assert lengths == (
        [None] * len(lengths)
        if first["turn_length_m"] is None
        else [approx(x) for x in first["turn_length_m"]]
    )
    assert doc["turns_per_coil"] == first["total_turns"]
    assert doc["total_turns"] == want["total_turns"]
    assert doc["build_height_m"] == approx(first["build_height_m"])
    assert doc["fill_factor"] == approx(first["fill_factor"])
    assert doc["wire_length_m"] == approx(want["wire_length_m"])
    assert doc["resistance_ohm"] == approx(want["resistance_ohm"])
    assert doc["finish_side"] == first["finish_side"]
    assert doc["fits"] is want["fits"]
    assert [c["total_turns"] for c in doc["coils"]] == [c["total_turns"] for c in want["coils"]]
    # the take-up over a turn: a round core draws evenly; a sharp w x t core's layer at r_l
    # draws fastest off a corner, (r_l + the half-diagonal), slowest along a flat (r_l + half the
    # smaller side)
    v = flat(YAML(typ="safe").load(path.read_text()))
    for x, r_l in zip(doc["layers"], first["radius_m"], strict=True):
        if v.get("bobbin.core") == "rect" and v.get("bobbin.core_width", 0):
            w, t = v["bobbin.core_width"], v["bobbin.core_depth"]
            r = v.get("bobbin.core_corner_radius", 0.0) + r_l
            reach = r + math.hypot(w / 2 + r_l - r, t / 2 + r_l - r)  # off a corner, square to its diagonal
            assert x["takeup_ratio"] == approx(reach / (r_l + min(w, t) / 2))
        elif v.get("bobbin.core_diameter", 0):
            assert x["takeup_ratio"] == 1.0
        else:
            assert x["takeup_ratio"] is None

    text = subprocess.run([str(WINDER), "check", str(path)], capture_output=True, text=True, timeout=60)
    assert text.returncode == out.returncode
    lines = text.stdout.splitlines()
    assert lines[0].startswith(f"job {want['job_id']}: ")
    for i, turns in enumerate(first["turns"]):  # the first table is coil 1's
        turn = "-" if first["turn_length_m"] is None else f"{first['turn_length_m'][i] * 1e3:.2f}"
        row = [str(i + 1), str(turns), f"{first['radius_m'][i] * 1e3:.3f}", turn]
        assert any(line.split()[:4] == row for line in lines), (row, text.stdout)
    assert f"turns          {first['total_turns']} per coil, {want['total_turns']} in all" in text.stdout
    fill = first["fill_factor"]
    assert f"fill factor    {'-' if fill is None else f'{fill:.3f}'} " in text.stdout
    side = {"start": "the start flange", "far": "the far flange"}[first["finish_side"]]
    assert f"finish side    {side} ({len(first['turns'])} layers)" in text.stdout
    if want["resistance_ohm"] is not None:
        assert f"resistance     {want['resistance_ohm']:.4g} ohm at 20 C" in text.stdout
        assert f"wire length    {want['wire_length_m']:.4g} m (" in text.stdout
    assert ("fits           yes" in text.stdout) is want["fits"]


# -- a job that does not fit: one line, the same words, everywhere ---------------------------

TOO_WIDE = (
    "interp_node:\n  ros__parameters:\n    job_id: too_wide\n    turns_per_layer: 20\n    layers: 2\n"
    "    poles: 1\n    bobbin:\n      window_width: 0.048\n"
)
WORDS = (
    "layer 1 needs 20 turns x 2.5 mm = 50.0 mm, the window is 48.0 mm wide: 2.0 mm over "
    "(at most 19 turns fit)"
)


def test_a_coil_that_does_not_fit_is_refused_in_one_line_by_check_and_run(tmp_path: Path) -> None:
    job = tmp_path / "too_wide.yaml"
    job.write_text(TOO_WIDE)
    out = subprocess.run([str(WINDER), "check", str(job)], capture_output=True, text=True, timeout=60)
    assert out.returncode == 2
    assert out.stderr == f"winder check: error: {WORDS}\n"
    assert f"fits           NO: {WORDS}" in out.stdout  # the report is printed first
    out = subprocess.run(
        [str(WINDER), "check", str(job), "--json"], capture_output=True, text=True, timeout=60
    )
    assert out.returncode == 2 and json.loads(out.stdout)["fits"] is False
    assert json.loads(out.stdout)["overflow"] == WORDS
    # options over the file: 19 turns fit
    out = subprocess.run(
        [str(WINDER), "check", str(job), "--turns-per-layer", "19"],
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert out.returncode == 0, out.stderr
    for argv in (["run", "--check", str(job)], ["run", str(job)]):
        out = subprocess.run([str(WINDER), *argv], capture_output=True, text=True, timeout=60)
        assert out.returncode == 2 and out.stdout == ""
        assert out.stderr == f"winder run: error: {job}: interp_node: {WORDS}\n"
    out = subprocess.run(
        [str(WINDER), "run", "--check", "--bobbin.window-width", "0.048", "--poles", "1"],
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert out.returncode == 2 and out.stderr == f"winder run: error: {WORDS}\n"


@pytest.mark.ros
def test_the_interp_node_refuses_a_coil_that_does_not_fit_and_keeps_running(
    tmp_path: Path, procs: Procs, ros: Any
) -> None:
    """At start (its parameters file): the words in its log, the node up and
    blocked. On ~/start_run: the words as the reason, nothing set, the node up;
    then a job file that fits runs and its bag names the file's sha256."""
    from support.ros_probe import get_params, start_run

    job = tmp_path / "too_wide.yaml"
    job.write_text(TOO_WIDE)
    p = procs.start("interp_node", "--params-file", str(job), "-p", "autostart:=false")
    wait.log_has(lambda: procs.log(p), WORDS, 30, "the interp node's refusal of the coil", running=p)
    assert p.poll() is None, procs.log(p)
    assert f"settings rejected at start: {WORDS}" in procs.log(p)
    assert procs.stop(p) == 0 and "Traceback" not in procs.log(p)

    bags = tmp_path / "bags"
    procs.start("sim_node", "-p", f"bag_dir:={bags}")
    procs.start("profile_node")
    p = procs.start("interp_node", "-p", "autostart:=false")
    refused = start_run(ros, {"job_id": "too_wide", "poles": 1, "bobbin.window_width": 0.048})
    assert not refused.successful and refused.reason == WORDS, refused.reason
    assert get_params(ros, "interp_node", ["job_id", "bobbin.window_width"]) == ["rw400", 0.0]  # untouched
    assert p.poll() is None
    assert not bags.exists() or not any(bags.iterdir())

    fits = tmp_path / "fits.yaml"
    fits.write_text(TOO_WIDE.replace("too_wide", "fits").replace("turns_per_layer: 20", "turns_per_layer: 4"))
    good = start_run(ros, {"job_file": str(fits)})
    assert good.successful, good.reason
    run_id = re.match(r"run (\S+) started", good.reason).group(1)  # type: ignore[union-attr]
    run = finished_run(bags, run_id)
    assert run.complete and run.plan.job.window_width == 0.048 and run.plan.job.layer_turns == 4
    assert run.plan.job_file_sha256 == hashlib.sha256(fits.read_bytes()).hexdigest()
    out = subprocess.run(
        [str(WINDER), "analyze", str(bags / run_id), "--json"], capture_output=True, text=True, timeout=120
    )
    assert out.returncode == 0, out.stderr
    assert json.loads(out.stdout)[0]["job_file_sha256"] == run.plan.job_file_sha256
    from support.ros_probe import set_params

    # what ~/start_run set was the run's: the node's settings are what they were before it
    assert get_params(ros, "interp_node", ["job_file", "job_file_sha256"]) == ["", ""]
    # the file set on the node, then a change of the job without the file: the hash no longer names it
    [res] = set_params(ros, "interp_node", {"job_file": str(fits)})
    assert res.successful, res.reason
    assert get_params(ros, "interp_node", ["job_file_sha256"]) == [run.plan.job_file_sha256]
    [res] = set_params(ros, "interp_node", {"layers": 1})
    assert res.successful, res.reason
    assert get_params(ros, "interp_node", ["job_file_sha256"]) == [""]
    assert p.poll() is None and "Traceback" not in procs.log(p)


@pytest.mark.ros
def test_winder_run_carries_the_job_files_hash_into_the_bag(tmp_path: Path, procs: Procs) -> None:
    from support.cell import only_bag, winder_run

    from winder.record.reader import read_run

    job = tmp_path / "fits.yaml"
    job.write_text(
        TOO_WIDE.replace("too_wide", "hashed").replace("turns_per_layer: 20", "turns_per_layer: 3")
    )
    out = winder_run(tmp_path, procs.domain, str(job), "--fork-steps-per-rev", "256")
    assert out.returncode == 0, out.stdout + out.stderr
    digest = hashlib.sha256(job.read_bytes()).hexdigest()
    assert f"(sha256 {digest})" in out.stdout
    bag = only_bag(tmp_path)
    assert read_run(bag).plan.job_file_sha256 == digest
    text = subprocess.run([str(WINDER), "analyze", str(bag)], capture_output=True, text=True, timeout=120)
    assert text.returncode == 0 and digest in text.stdout, text.stdout + text.stderr
