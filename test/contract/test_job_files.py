"""Job files: a job as a ROS 2 parameters file that
``winder run``, the nodes' ``--params-file`` and the interp node's
``job_file`` parameter all take.

Expected values come from the file as ruamel reads it here, flattened by a
loop in the test; the runs are the real node executables started one by one.
"""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from conftest import Procs
from ruamel.yaml import YAML
from support import wait
from support.bags import finished_run
from support.paths import ROOT

from winder.contract.jobfile import SECTION_ALIASES, JobFileError, load_job_file
from winder.record.bag import bags_in
from winder.record.reader import read_run

JOBS = sorted((ROOT / "jobs").glob("*.yaml"))
WINDER = Path(sys.executable).with_name("winder")


def flat(doc: Any) -> dict[str, dict[str, Any]]:
    """node -> {dotted name: value}, by hand."""
    out: dict[str, dict[str, Any]] = {}
    for node, body in doc.items():
        stack = [("", body["ros__parameters"])]
        values: dict[str, Any] = {}
        while stack:
            prefix, d = stack.pop()
            for k, v in d.items():
                name = f"{prefix}.{k}" if prefix else k
                if isinstance(v, dict):
                    stack.append((name, v))
                else:
                    values[name] = v
        out[node] = values
    return out


def test_three_job_files_ship_and_load_as_written() -> None:
    assert {p.stem for p in JOBS} >= {"rw400", "stator_12", "armature_fine"}
    for path in JOBS:
        want = flat(YAML(typ="safe").load(path.read_text()))
        got = load_job_file(path)
        for node, values in want.items():  # the sim_node section is the consumer's
            assert got[SECTION_ALIASES.get(node, node)] == pytest.approx(values), (path.name, node)


@pytest.mark.parametrize("path", JOBS, ids=[p.stem for p in JOBS])
def test_winder_run_check_takes_a_job_file(path: Path) -> None:
    out = subprocess.run(
        [str(WINDER), "run", "--check", str(path)], capture_output=True, text=True, timeout=60
    )
    job = flat(YAML(typ="safe").load(path.read_text()))["interp_node"]
    assert out.returncode == 0, out.stderr
    assert f"job {job['job_id']}:" in out.stdout


BAD = [
    ("", "a job file is a ROS 2 parameters file"),
    ("- 1\n- 2\n", "a job file is a ROS 2 parameters file"),
    ("a: [1\n", "not YAML at line 2"),
    ("spindle_node:\n  ros__parameters: {x: 1}\n", "section 'spindle_node': not a winder node"),
    ("interp_node: {layers: 2}\n", "must hold exactly one key, ros__parameters"),
    ("interp_node:\n  ros__parameters: 3\n", "interp_node.ros__parameters must be a map"),
    ("interp_node:\n  ros__parameters: {turn_per_layer: 3}\n", "interp_node has no setting 'turn_per_layer'"),
    (
        "interp_node:\n  ros__parameters: {turns_per_layer: 0}\n",
        "interp_node.ros__parameters.turns_per_layer: turns_per_layer=0 is invalid: must be in [1, 100000]",
    ),
    ("interp_node:\n  ros__parameters: {layers: [1, 2]}\n", "layers=[1, 2] is invalid"),
    ("interp_node:\n  ros__parameters: {layers: null}\n", "layers='null' is invalid"),  # ROS: the text null
    (
        "sim_node:\n  ros__parameters: {fork: {J: -1}}\n",
        "sim_node.ros__parameters.fork.J: fork.J=-1 is invalid",
    ),
    ("/**:\n  ros__parameters: {flux: 1}\n", "no winder node has a setting 'flux'"),
    (
        "consumer:\n  ros__parameters: {fork: {J: -1}}\n",
        "consumer.ros__parameters.fork.J: fork.J=-1 is invalid",
    ),
    ("consumer:\n  ros__parameters: {flux: 1}\n", "consumer has no setting 'flux'"),
    (
        "sim_node:\n  ros__parameters: {model: linear}\nconsumer:\n  ros__parameters: {model: nonlinear}\n",
        "sections 'sim_node' and 'consumer' both hold the step consumer's settings",
    ),
    (
        "consumer:\n  ros__parameters: {model: linear}\n"
        "/cell1/sim_node:\n  ros__parameters: {publish_rate: 9.0}\n",
        "sections 'consumer' and '/cell1/sim_node' both hold the step consumer's settings",
    ),
    ("axes:\n  ros__parameters: {model: linear}\n", "section 'axes': not a winder node"),
    # aliases: ROS refuses them in a parameters file, and so does the loader, before
    # anything expands one (a cycle, an alias bomb: they ended interp_node or grew --check to GBs)
    ("interp_node: &r {ros__parameters: {x: *r}}\n", "line 1: an alias (*r)"),
    ("interp_node:\n  ros__parameters: &p {turns_per_layer: 3, more: *p}\n", "an alias (*p)"),
    # nine lines of nested aliases inside ros__parameters: 10**7 values once expanded
    (
        "interp_node:\n  ros__parameters:\n    a: &a [1,1,1,1,1,1,1,1,1,1]\n"
        + "".join(
            f"    {n}: &{n} [{','.join([f'*{m}'] * 10)}]\n" for m, n in zip("abcde", "bcdef", strict=True)
        )
        + "    g: [*f,*f,*f,*f,*f,*f,*f,*f,*f,*f]\n",
        "line 4: an alias (*a): ROS 2 parameters files have none",
    ),
    ("interp_node:\n  ros__parameters:\n    turns_per_layer:\n", "no value for 'turns_per_layer'"),
    ("interp_node:\n  ros__parameters: {layers: 2, layers: 3}\n", "key 'layers' given twice"),
    ("interp_node:\n  ros__parameters: {layers: 2}\n---\n{}\n", "a second YAML document"),
    ("interp_node:\n  ros__parameters: {turns_per_layer: 0o17}\n", "turns_per_layer='0o17' is invalid"),
    ("interp_node:\n  ros__parameters: {job_id: 017}\n", "job_id=15 is invalid"),
    (
        "interp_node:\n  ros__parameters: {turns_per_layer: 100, coil_length: 0.01}\n",
        "interp_node: layer 1 needs 100 turns x 2.5 mm = 250.0 mm",
    ),
    (
        "profile_node:\n  ros__parameters: {profile: trapezoid, a_max: 1.0e-12}\n",
        "profile_node: profile=trapezoid",
    ),
]


@pytest.mark.parametrize(("text", "why"), BAD, ids=[f"bad{i}" for i in range(len(BAD))])
def test_a_bad_job_file_is_refused_in_one_line(tmp_path: Path, text: str, why: str) -> None:
    path = tmp_path / "job.yaml"
    path.write_text(text)
    with pytest.raises(JobFileError) as err:
        load_job_file(path)
    assert str(err.value).startswith(f"{path}: ") and why in str(err.value), str(err.value)
    out = subprocess.run(
        [str(WINDER), "run", "--check", str(path)], capture_output=True, text=True, timeout=60
    )
    assert out.returncode == 2 and "Traceback" not in out.stderr
    assert len(out.stderr.strip().splitlines()) == 1 and why in out.stderr, out.stderr


def test_the_consumer_section_by_either_name(tmp_path: Path) -> None:
    """``consumer`` (name-free) and ``sim_node`` (the stock node's name, which
    ``ros2 run ... --params-file`` applies) are one section: the loader
    returns it under "consumer", checked against the same settings; a
    namespace in front is allowed, and ``/**`` values reach it too."""
    for section in ("consumer", "sim_node", "/cell1/consumer", "/cell1/sim_node"):
        path = tmp_path / "job.yaml"
        path.write_text(
            f"{section}:\n  ros__parameters: {{model: nonlinear, fork: {{J: 2.0e-4}}}}\n"
            "/**:\n  ros__parameters: {publish_rate: 500.0}\n"
        )
        got = load_job_file(path)
        assert set(got) == {"interp_node", "profile_node", "consumer"}
        assert got["consumer"] == {"model": "nonlinear", "fork.J": 2.0e-4, "publish_rate": 500.0}, section


def test_a_job_files_switches_are_not_dropped(tmp_path: Path) -> None:
    """A yes/no setting in a job file (record: false, real_time: true) stands
    when the command line does not give the flag: a flag not given is no
    value (it used to be the default, which silently beat the file's)."""
    from winder.cli.commands import build_parser, job_file, values_from_args
    from winder.contract.params import SIM_SPECS

    path = tmp_path / "job.yaml"
    path.write_text("consumer:\n  ros__parameters: {record: false, real_time: true}\n")
    args = build_parser().parse_args(["run", str(path)])
    sim = values_from_args(args, SIM_SPECS, job_file(args)["consumer"])
    assert sim["record"] is False and sim["real_time"] is True
    args = build_parser().parse_args(["run", str(path), "--no-record"])
    assert values_from_args(args, SIM_SPECS, job_file(args)["consumer"])["record"] is False
    args = build_parser().parse_args(["run"])
    sim = values_from_args(args, SIM_SPECS, {})
    assert sim["record"] is True and sim["real_time"] is False  # the defaults, with no file


def test_a_missing_or_huge_job_file_is_refused(tmp_path: Path) -> None:
    with pytest.raises(JobFileError, match="no such job file"):
        load_job_file(tmp_path / "nope.yaml")
    big = tmp_path / "big.yaml"
    big.write_text("#" * (2 << 20))
    with pytest.raises(JobFileError, match="more than a job file holds"):
        load_job_file(big)
    with pytest.raises(JobFileError, match="not a file"):
        load_job_file(tmp_path)


def test_command_line_options_override_the_file() -> None:
    def check(*options: str) -> subprocess.CompletedProcess[str]:
        return subprocess.run(
            [str(WINDER), "run", "--check", str(ROOT / "jobs" / "stator_12.yaml"), *options],
            capture_output=True,
            text=True,
            timeout=60,
        )

    # 3 poles instead of 12: the file's overrides of coils 4 to 12 no longer fit, and say so
    out = check("--poles", "3")
    assert out.returncode == 2 and "coil_overrides: coil 4 is not in [1, 3] (poles)" in out.stderr, out.stderr
    out = check("--poles", "3", "--coil-overrides", "2:direction=ccw")
    assert out.returncode == 0, out.stderr
    # 3 x 3 layers + 2 pole moves = 11 segments
    assert "in 11 segments" in out.stdout, out.stdout


SMALL_JOB = """\
interp_node:
  ros__parameters:
    job_id: filed
    turns_per_layer: 3
    layers: 1
    poles: 2
    fork_steps_per_rev: 512
profile_node:
  ros__parameters:
    profile: trapezoid
    v_max: 3000.0
    a_max: 30000.0
sim_node:
  ros__parameters:
    publish_rate: 500.0
    fork:
      J: 2.0e-4
"""


@pytest.mark.ros
def test_the_nodes_take_a_job_file_as_their_params_file(tmp_path: Path, procs: Procs) -> None:
    """ros2 run ... --ros-args --params-file job.yaml on each node: each takes
    its section; the bag holds the file's job, ramp and motor."""
    job = tmp_path / "job.yaml"
    job.write_text(SMALL_JOB)
    bags = tmp_path / "bags"
    procs.start("sim_node", "--params-file", str(job), "-p", f"bag_dir:={bags}")
    procs.start("profile_node", "--params-file", str(job))
    procs.start("interp_node", "--params-file", str(job))
    # a bag has its metadata.yaml from its first moment: wait for the run's final report in it
    wait.until(
        lambda: (
            (metas := list(bags.glob("*/metadata.yaml"))) and read_run(metas[0].parent).report.get("state")
        ),
        60,
        f"a bag in {bags} with its run's final report",
        heard=lambda: (
            sorted(str(m.relative_to(bags)) for m in bags.glob("*/*")) if bags.is_dir() else "no bags"
        ),
        poll=0.2,  # each look reads the bag
    )
    [meta] = list(bags.glob("*/metadata.yaml"))
    run = read_run(meta.parent)
    assert run.complete and run.job_id == "filed" and run.plan.job.fork_steps_per_rev == 512
    assert run.profile == "trapezoid" and run.profile_config["v_max"] == 3000.0
    assert run.sim_config is not None and run.sim_config.axes["fork"].J == 2.0e-4
    assert run.sim_config.publish_rate == 500.0


@pytest.mark.ros
def test_the_interp_node_takes_a_job_file_in_one_start_run_call(
    tmp_path: Path, procs: Procs, ros: Any
) -> None:
    """~/start_run with job_file: the file's job and its ramp (carried with the
    job: the profile node's own is scurve) in one call; a bad file sets
    nothing and starts nothing, with the file's reason."""
    from support.ros_probe import get_params, start_run

    job = tmp_path / "job.yaml"
    job.write_text(SMALL_JOB)
    bad = tmp_path / "bad.yaml"
    bad.write_text("interp_node:\n  ros__parameters: {poles: 0}\n")
    bags = tmp_path / "bags"
    procs.start("sim_node", "-p", f"bag_dir:={bags}")
    procs.start("profile_node")
    procs.start("interp_node", "-p", "autostart:=false")

    def start(path: Path) -> Any:
        return start_run(ros, {"job_file": str(path)})

    refused = start(bad)
    assert not refused.successful and str(bad) in refused.reason and "poles=0" in refused.reason, (
        refused.reason
    )
    cycle = tmp_path / "recur.yaml"
    cycle.write_text("interp_node: &r {ros__parameters: {x: *r}}\n")
    refused = start(cycle)  # it ended the node (RecursionError) before aliases were bounded
    assert not refused.successful and "an alias (*r)" in refused.reason, refused.reason
    assert get_params(ros, "interp_node", ["job_file", "job_id"]) == ["", "rw400"]
    started = start(job)
    assert started.successful, started.reason
    run_id = re.match(r"run (\S+) started", started.reason).group(1)  # type: ignore[union-attr]
    run = finished_run(bags, run_id)
    assert run.complete and run.job_id == "filed" and run.plan.job.poles == 2
    assert run.profile == "trapezoid" and run.profile_config["ramp_source"] == "job"


@pytest.mark.ros
def test_a_job_with_coil_overrides_runs_through_the_nodes(tmp_path: Path, procs: Procs) -> None:
    """A job file whose second coil is wound backward with more turns and whose
    third has one layer: the recorded steps are the interpolation of those
    segments, nothing lost, and the analysis measures every layer against its
    own line (eq. 7 of the axes as small as for a plain job)."""
    from winder.analysis.metrics import analyze
    from winder.motion.interp import interpolate
    from winder.motion.job import Job

    fields = {"poles": 3, "turns_per_layer": 4, "layers": 2, "fork_steps_per_rev": 512}
    overrides = "2:turns_per_layer=6,direction=ccw; 3:layers=1"
    body = "\n".join(f"    {k}: {v}" for k, v in fields.items())
    job_file = tmp_path / "coils.yaml"
    job_file.write_text(f'interp_node:\n  ros__parameters:\n{body}\n    coil_overrides: "{overrides}"\n')
    bags = tmp_path / "bags"
    out = subprocess.run(
        [str(WINDER), "run", str(job_file), "--bag-dir", str(bags)],
        env=procs.env,
        capture_output=True,
        text=True,
        timeout=180,
    )
    assert out.returncode == 0, out.stdout + out.stderr
    [bag] = bags_in(bags)
    run = read_run(bag)
    assert run.complete and not run.errors
    job = Job(**fields, coil_overrides=overrides)
    segs = job.segments()
    assert [s.delta[1] for s in segs if s.kind == "layer"] == [2048, 2048, -3072, -3072, 2048]
    want = np.concatenate([interpolate(s.start, s.delta) for s in segs])
    assert np.array_equal(run.steps[:, 2:], want)
    a = analyze(run)
    assert a.lost_steps == 0 and len(a.command.layers) == 5
    assert a.actual is not None and a.actual.mean < 2 * a.command.mean, (a.actual.mean, a.command.mean)


#: scalars YAML 1.2 (ruamel's default) and ROS's parameters-file parser read
#: differently, each in a setting of its type: (setting, scalar as written)
TRICKY = [
    ("turns_per_layer", "0o17"),  # YAML 1.2: 15; ROS: the text 0o17
    ("turns_per_layer", "017"),  # YAML 1.2: 17; ROS (strtol): octal 15
    ("turns_per_layer", "0x1F"),
    ("turns_per_layer", "1_000"),  # YAML 1.2: 1000; ROS: a text
    ("turns_per_layer", "1e3"),
    ("turns_per_layer", "08"),  # ROS: not octal, the double 8.0
    ("turns_per_layer", "~"),  # ROS: the text ~
    ("turns_per_layer", "'12'"),
    ("turns_per_layer", "yes"),  # ROS: true
    ("wire_diameter", ".inf"),
    ("wire_diameter", "0x1p-9"),  # ROS (strtod): a hex float
    ("autostart", "no"),  # YAML 1.2: a text; ROS: false
    ("autostart", "off"),
    ("autostart", "'no'"),
    ("job_id", "'12'"),
    ("job_id", "017"),
    ("job_id", "yes"),
    ("job_id", "0o17"),
]


@pytest.mark.ros
def test_check_and_the_node_read_every_scalar_the_same(tmp_path: Path, procs: Procs, ros: Any) -> None:
    """Each tricky scalar in a job file: ``winder run --check`` and a real
    interp_node given the file (``--params-file``: ROS's own parser) agree
    on it: both refuse it, or both take the same value."""
    from support.ros_probe import get_params

    from winder.contract.params import INTERP_SPECS

    cases = []
    for i, (name, text) in enumerate(TRICKY):
        path = tmp_path / f"s{i}.yaml"
        path.write_text(f"/s{i}/interp_node:\n  ros__parameters:\n    {name}: {text}\n")
        try:
            value, refused = load_job_file(path)["interp_node"][name], ""
        except JobFileError as exc:
            value, refused = None, str(exc)
        check = subprocess.run(
            [str(WINDER), "run", "--check", str(path)], capture_output=True, text=True, timeout=60
        )
        assert check.returncode == (2 if refused else 0) and "Traceback" not in check.stderr, check.stderr
        assert value != INTERP_SPECS[name].default, (name, text)  # a refusal shows as the default
        procs.start("interp_node", "-r", f"__ns:=/s{i}", "--params-file", str(path))
        cases.append((i, name, text, value, refused))
    verdicts = {}
    for i, name, text, value, refused in cases:
        (got,) = get_params(ros, f"s{i}/interp_node", [name])
        node_took = got != INTERP_SPECS[name].default
        verdicts[text, name] = (not refused, value)
        assert node_took == (not refused), (name, text, got, refused)
        if node_took:
            assert got == value and type(got) is type(value), (name, text, got, value)
    # what ROS makes of them, as the table above says
    assert verdicts["017", "turns_per_layer"] == (True, 15)
    assert verdicts["0o17", "turns_per_layer"][0] is False
    assert verdicts["1_000", "turns_per_layer"][0] is False
    assert verdicts["08", "turns_per_layer"] == (True, 8)
    assert verdicts["no", "autostart"] == (True, False)
    assert verdicts["'12'", "job_id"] == (True, "12") and verdicts["0o17", "job_id"] == (True, "0o17")


@pytest.mark.ros
def test_winder_run_gives_the_nodes_the_values_it_checked(tmp_path: Path, procs: Procs) -> None:
    """A text that ROS would read as a number or a bool (job_id '017', 'yes')
    reaches the nodes as that text: winder run passed it unquoted (-p
    job_id:=017, the integer 15), and the node refused the job --check took."""
    for job_id in ("017", "yes"):
        job = tmp_path / f"{job_id}.yaml"
        small = "turns_per_layer: 2, layers: 1, poles: 1"
        job.write_text(f"interp_node:\n  ros__parameters: {{job_id: '{job_id}', {small}}}\n")
        bags = tmp_path / f"bags_{job_id}"
        r = subprocess.run(
            [str(WINDER), "run", str(job), "--bag-dir", str(bags), "--start-timeout", "30"],
            capture_output=True,
            text=True,
            timeout=120,
            env=procs.env,
            stdin=subprocess.DEVNULL,
        )
        assert r.returncode == 0, r.stdout + r.stderr
        (bag,) = bags_in(bags)
        assert read_run(bag).job_id == job_id
