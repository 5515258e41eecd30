"""The cell's Wind action (winder_interfaces/action/Wind on winder/wind),
driven by an rclpy ActionClient against the real interp, profile and sim
nodes, as an integrator's controller drives it: a goal winds a part (its
feedback and a result naming the run's complete bag), a cancel is an abort,
a goal while a run goes on is refused with the reason, a job that is not
valid is refused in `winder check`'s words, and the server goes on serving
after each.

Oracles: the job's step count from winder.motion.job.Job (the interpolation's
own segments, computed here), the bag the run wrote (read by rosbags and by
mcap), and the consumer's final report in it.
"""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

import pytest
from conftest import Procs, bag_closed, final_report, rosbags_read
from support import wait
from support.cli import run_cli
from support.paths import ROOT
from support.ros_probe import get_params, ready_states

from winder.contract.params import INTERP_SPECS
from winder.motion.job import Job

pytestmark = pytest.mark.ros

#: a small job: 2 coils of one 8-turn layer, 512 fork steps a turn (a second or two of motion)
JOB = {"turns_per_layer": 8, "layers": 1, "poles": 2, "fork_steps_per_rev": 512}
#: a long one, for a run to cancel or to be busy with (paced in real time: many seconds)
LONG = {"turns_per_layer": 60, "layers": 4, "poles": 4, "fork_steps_per_rev": 512}


def job_text(fields: dict[str, Any], job_id: str) -> str:
    """A job file's text, as `winder run` reads one."""
    lines = ["interp_node:", "  ros__parameters:", f"    job_id: {job_id}"]
    lines += [f"    {k}: {v}" for k, v in fields.items()]
    return "\n".join(lines) + "\n"


def cell(procs: Procs, tmp: Path, ros: Any, client: Any, *, real_time: bool, **interp: object) -> Path:
    """The cell's three nodes, the consumer and the profile node ready, the
    action server matched by ``client``; its bag directory."""
    bags = tmp / "bags"
    states = ready_states(ros)
    procs.start(
        "interp_node", "-p", "autostart:=false", *(a for k, v in interp.items() for a in ("-p", f"{k}:={v}"))
    )
    procs.start("profile_node")
    procs.sim = procs.start(  # type: ignore[attr-defined]
        "sim_node", "-p", f"bag_dir:={bags}", "-p", f"real_time:={str(real_time).lower()}"
    )
    wait.spin_until(
        ros,
        lambda: states.get("consumer") == "ready" and states.get("profile") == "ready",
        60,
        "consumer and profile node ready on winder/ready",
        heard=lambda: states,
    )
    wait.spin_until(ros, client.server_is_ready, 60, "the interp node's winder/wind action server")
    return bags


class Goal:
    """One goal sent by an ActionClient: its feedback as it comes, its result."""

    def __init__(
        self,
        ros: Any,
        client: Any,
        job: str = "",
        overrides: tuple[str, ...] = (),
        goal_sha256: str = "",
        **facts: str,
    ) -> None:
        from winder_interfaces.action import Wind

        self.ros = ros
        self.feedback: list[Any] = []
        sent = client.send_goal_async(
            Wind.Goal(job=job, overrides=list(overrides), goal_sha256=goal_sha256, **facts),
            feedback_callback=lambda m: self.feedback.append(m.feedback),
        )
        self.handle = wait.spin_until(ros, lambda: sent.done() and sent.result(), 30, "the goal's acceptance")
        assert self.handle.accepted
        self.result_future = self.handle.get_result_async()

    def result_after(self, act: Any, timeout: float = 120) -> tuple[int, Any]:
        """(status, result), calling ``act()`` (which must not spin) every
        second while the goal goes on (a resume for a stop that waits for one)."""
        import time

        asked = [0.0]

        def ended() -> bool:
            if self.result_future.done():
                return True
            if time.monotonic() - asked[0] > 1.0:
                asked[0] = time.monotonic()
                act()
            return False

        wait.spin_until(self.ros, ended, timeout, "the goal's result", heard=lambda: self.feedback[-1:])
        return self.result(timeout)

    def result(self, timeout: float = 120) -> tuple[int, Any]:
        """(status, result) once the goal ended."""
        wait.spin_until(
            self.ros,
            self.result_future.done,
            timeout,
            "the goal's result",
            heard=lambda: self.feedback[-1:] or "no feedback",
        )
        answer = self.result_future.result()
        return answer.status, answer.result


def mcap_messages(bag: Path, topic: str, msgtype: str) -> list[Any]:
    """The messages on ``topic``, read with the mcap library: its schema must
    be ``msgtype`` in ros2msg (with the types it is made of after it), each
    message decoded by a rosbags store made from that schema alone."""
    from mcap.reader import make_reader
    from rosbags.typesys import Stores, get_types_from_msg, get_typestore

    [path] = bag.glob("*.mcap")
    out = []
    with path.open("rb") as f:
        for schema, _channel, message in make_reader(f).iter_messages(topics=[topic]):
            assert (schema.name, schema.encoding) == (msgtype, "ros2msg")
            store = get_typestore(Stores.EMPTY)
            text = schema.data.decode()
            main, _, deps = text.partition("\n" + "=" * 80 + "\n")
            types = get_types_from_msg(main, schema.name)
            for dep in deps.split("=" * 80 + "\n") if deps else []:
                head, _, body = dep.partition("\n")
                types.update(get_types_from_msg(body, head.removeprefix("MSG: ").strip()))
            store.register(types)
            out.append(store.deserialize_cdr(message.data, schema.name))
    return out


def latched_report(ros: Any) -> Any:
    """The last final report on /winder/report, as a subscriber that comes
    after it gets it (latched)."""
    from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy

    from winder_interfaces.msg import JobReport

    got: list[Any] = []
    qos = QoSProfile(
        depth=1, reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.TRANSIENT_LOCAL
    )
    sub = ros.create_subscription(JobReport, "/winder/report", got.append, qos)
    try:
        wait.spin_until(ros, lambda: got, 30, "the latched final report on /winder/report")
    finally:
        ros.destroy_subscription(sub)
    return got[-1]


@pytest.fixture
def client(ros: Any) -> Any:
    from rclpy.action import ActionClient

    from winder_interfaces.action import Wind

    c = ActionClient(ros, Wind, "/winder/wind")
    yield c
    c.destroy()


def test_a_goal_winds_a_part(procs: Procs, tmp_path: Path, ros: Any, client: Any) -> None:
    from action_msgs.msg import GoalStatus

    bags = cell(procs, tmp_path, ros, client, real_time=False)
    goal = Goal(ros, client, job_text(JOB, "part_a"))
    status, result = goal.result()
    total = Job(**JOB, job_id="part_a").total_steps  # the oracle: the job's own segments
    assert status == GoalStatus.STATUS_SUCCEEDED, result.message
    assert result.success and result.run_id.startswith("part_a_")
    assert result.message == f"job part_a: complete, {total}/{total} steps"
    # the result names the run's bag, closed, holding the same final report
    bag = Path(result.bag_path)
    assert bag.parent == bags and bag.name == result.run_id and bag_closed(bag)
    # ... and its part, which `winder parts show` finds in the index beside the bag, naming that bag
    assert result.part_id, result
    shown = run_cli("parts", "show", result.part_id, "--bag-dir", str(bags), "--json")
    assert shown.returncode == 0, shown.stdout + shown.stderr
    part = json.loads(shown.stdout)
    assert (part["part_id"], part["run_id"], part["bag"], part["state"]) == (
        result.part_id,
        result.run_id,
        str(bag.resolve()),
        "done",
    )
    report = result.report
    assert (report.state, report.run_id, report.steps_done, report.steps_total) == (
        "done",
        result.run_id,
        total,
        total,
    )
    read = rosbags_read(bag)
    recorded = final_report(read)
    assert recorded["state"] == "done" and int(recorded["steps_done"]) == total
    # the typed cell state, read back by rosbags (from the bag's own schema) and by mcap
    states = [m for _, m in read["/winder/state"]]
    assert [(m.state, m.run_id, m.node) for m in states] == [
        ("running", result.run_id, "sim_node"),
        ("done", result.run_id, "sim_node"),
    ]
    assert (states[-1].coil, states[-1].layer, states[-1].turn) == (2, 1, 8)
    assert [m.state for m in mcap_messages(bag, "/winder/state", "winder_interfaces/msg/CellState")] == [
        "running",
        "done",
    ]
    # the job description, typed: the same by mcap's schema as by rosbags'
    [job] = mcap_messages(bag, "/winder/job", "winder_interfaces/msg/JobDescription")
    [(_, recorded_job)] = read["/winder/job"]
    assert (job.run_id, job.job_id, job.total_steps) == (result.run_id, "part_a", total)
    assert [(s.kind, list(s.delta), s.steps) for s in job.segments] == [
        (s.kind, list(s.delta), s.steps) for s in recorded_job.segments
    ]
    assert [(s.kind, list(s.delta), s.steps) for s in job.segments] == [
        (str(s.kind), list(s.delta), s.steps) for s in Job(**JOB, job_id="part_a").segments()
    ]
    # the final report, typed on winder/report: in the bag, and latched for a late reader
    [(_, typed)] = read["/winder/report"]
    [typed_by_mcap] = mcap_messages(bag, "/winder/report", "winder_interfaces/msg/JobReport")
    assert typed.node == typed_by_mcap.node == report.node == "sim_node"
    for name in ("state", "run_id", "steps_done", "steps_total", "steps_missing", "bag"):
        assert getattr(typed, name) == getattr(typed_by_mcap, name) == getattr(report, name), name
    assert {kv.key: kv.value for kv in typed.extra} == {kv.key: kv.value for kv in report.extra}
    late = latched_report(ros)
    assert (late.run_id, late.state, late.node, late.steps_done) == (result.run_id, "done", "sim_node", total)
    extra = {kv.key: kv.value for kv in report.extra}
    assert extra and all(recorded[k] == v for k, v in extra.items())
    # feedback: the run's id, steps that only grow, up to the total, where they reached
    assert goal.feedback, "no feedback"
    assert {f.run_id for f in goal.feedback} == {result.run_id}
    done = [f.steps_done for f in goal.feedback]
    assert done == sorted(done) and done[-1] == total  # the last: where the run ended
    last = goal.feedback[-1]
    assert (last.state, last.coil, last.layer, last.turn) == ("done", 2, 1, 8), last  # the job's last turn
    assert all(f.steps_total == total for f in goal.feedback)
    assert all(1 <= f.coil <= JOB["poles"] and f.layer <= JOB["layers"] for f in goal.feedback)
    assert all(f.turn <= JOB["turns_per_layer"] * JOB["layers"] for f in goal.feedback)
    assert all(math.isnan(f.tension_n) for f in goal.feedback)  # no core: no wire simulated


def test_a_cancel_aborts_the_run_and_the_cell_takes_the_next(
    procs: Procs, tmp_path: Path, ros: Any, client: Any
) -> None:
    from action_msgs.msg import GoalStatus

    cell(procs, tmp_path, ros, client, real_time=True)
    goal = Goal(ros, client, job_text(LONG, "long"))
    wait.spin_until(
        ros,
        lambda: any(f.steps_done > 0 for f in goal.feedback),
        60,
        "feedback of steps executed",
        heard=lambda: goal.feedback[-1:],
    )
    canceling = goal.handle.cancel_goal_async()
    wait.spin_until(ros, canceling.done, 30, "the cancel's reply")
    assert canceling.result().goals_canceling, "cancel refused"
    status, result = goal.result()
    total = Job(**LONG, job_id="long").total_steps
    assert status == GoalStatus.STATUS_CANCELED, result.message
    assert not result.success and result.report.state == "aborted"
    assert 0 < result.report.steps_done < total
    assert result.message.startswith("job long: aborted, the axes at rest")
    assert bag_closed(Path(result.bag_path))
    assert final_report(rosbags_read(Path(result.bag_path)))["state"] == "aborted"
    assert any(f.state == "aborting" for f in goal.feedback) or goal.feedback[-1].state == "aborted"
    # the cell is ready again: the next goal winds its part
    status, result = Goal(ros, client, job_text(JOB, "after")).result()
    assert status == GoalStatus.STATUS_SUCCEEDED, result.message


def test_a_goal_while_a_run_goes_on_is_refused_and_the_run_goes_on(
    procs: Procs, tmp_path: Path, ros: Any, client: Any
) -> None:
    from action_msgs.msg import GoalStatus

    cell(procs, tmp_path, ros, client, real_time=True)
    busy = {**JOB, "turns_per_layer": 30}  # a few seconds in real time
    first = Goal(ros, client, job_text(busy, "first"))
    wait.spin_until(ros, lambda: first.feedback, 60, "the first goal's feedback")
    status, result = Goal(ros, client, job_text(JOB, "second")).result(30)
    assert status == GoalStatus.STATUS_ABORTED
    assert not result.success and not result.run_id and not result.bag_path
    run_id = first.feedback[0].run_id
    assert f"run {run_id} is running" in result.message
    assert result.message.endswith("start refused, the running job goes on")
    status, result = first.result()
    assert status == GoalStatus.STATUS_SUCCEEDED and result.run_id == run_id, result.message


def test_a_job_that_is_not_valid_is_refused_with_its_reason(
    procs: Procs, tmp_path: Path, ros: Any, client: Any
) -> None:
    from action_msgs.msg import GoalStatus

    cell(procs, tmp_path, ros, client, real_time=False)
    turns = INTERP_SPECS["turns_per_layer"]
    refused = {
        "interp_node: [": "job rejected: goal job: not YAML at line 1",
        "interp_node:\n  ros__parameters:\n    turns: 3\n": (
            "job rejected: goal job: interp_node.ros__parameters.turns: interp_node has no setting 'turns'"
        ),
        job_text({**JOB, "layers": 0}, "zero"): "job rejected: goal job: interp_node.ros__parameters.layers",
    }
    for text, why in refused.items():
        status, result = Goal(ros, client, text).result(30)
        assert status == GoalStatus.STATUS_ABORTED and not result.success
        assert result.message.startswith(why), result.message
    for overrides, why in {
        # the setting's own range, as `winder ctl start --set` says it
        ("turns_per_layer=0",): f"turns_per_layer=0 is invalid: must be in {turns.range_text()}",
        ("v_max=2",): "overrides v_max: the interp node has no setting 'v_max'",
        ("turns_per_layer",): "overrides 'turns_per_layer' is invalid: must be key=value",
    }.items():
        status, result = Goal(ros, client, job_text(JOB, "o"), overrides).result(30)
        assert status == GoalStatus.STATUS_ABORTED and why in result.message, result.message
    # still serving: a valid goal, with an override that wins over its job
    status, result = Goal(ros, client, job_text(JOB, "fine"), ("turns_per_layer=4",)).result()
    assert status == GoalStatus.STATUS_SUCCEEDED, result.message
    total = Job(**{**JOB, "turns_per_layer": 4}, job_id="fine").total_steps
    assert result.report.steps_done == total


def test_the_feedback_carries_the_wires_tension(procs: Procs, tmp_path: Path, ros: Any, client: Any) -> None:
    """A job on a core (its wire simulated): the feedback's tension is the
    consumer's, within the least and peak tension its final report gives.
    The next goal's job text is wound as it says (a whole job: nothing of
    the core job's settings left)."""
    from action_msgs.msg import GoalStatus

    cell(procs, tmp_path, ros, client, real_time=False)
    job = (ROOT / "jobs" / "ortho_round.yaml").read_text()
    goal = Goal(ros, client, job, ("layers=2",))
    status, result = goal.result()
    assert status == GoalStatus.STATUS_SUCCEEDED, result.message
    extra = {kv.key: kv.value for kv in result.report.extra}
    low, high = float(extra["tension_min_n"]), float(extra["tension_peak_n"])
    seen = [f.tension_n for f in goal.feedback if not math.isnan(f.tension_n)]
    assert seen, [f.tension_n for f in goal.feedback]
    # the report rounds to 3 decimals
    assert all(low - 1e-3 <= t <= high + 1e-3 for t in seen), (low, high, seen)
    # a job text is a whole job: the next goal's is wound as it says, nothing of the last one's left
    status, result = Goal(ros, client, job_text(JOB, "after_core")).result()
    assert status == GoalStatus.STATUS_SUCCEEDED, result.message
    assert result.report.steps_total == Job(**JOB, job_id="after_core").total_steps
    assert not {kv.key for kv in result.report.extra} & {"tension_peak_n", "tension_min_n"}  # no core now


def test_a_goal_whose_consumer_dies_ends(procs: Procs, tmp_path: Path, ros: Any, client: Any) -> None:
    """The sim node killed (SIGKILL) mid-run: no final report will come. The
    goal ends ABORTED once the interp node's stall_abort has passed without
    word of the run, saying it gave the run up, and the server takes the
    next goal."""
    import signal

    from action_msgs.msg import GoalStatus

    cell(procs, tmp_path, ros, client, real_time=True, stall_abort=3.0)
    goal = Goal(ros, client, job_text(LONG, "orphan"))
    wait.spin_until(
        ros, lambda: any(f.steps_done > 0 for f in goal.feedback), 60, "feedback of steps executed"
    )
    procs.sim.send_signal(signal.SIGKILL)  # type: ignore[attr-defined]
    status, result = goal.result(60)
    assert status == GoalStatus.STATUS_ABORTED and not result.success, result.message
    assert "given up" in result.message, result.message
    # the server serves on: a goal now gets its answer
    status, result = Goal(ros, client, "interp_node: [").result(60)
    assert status == GoalStatus.STATUS_ABORTED and result.message.startswith("job rejected: goal job"), result


def test_a_job_cut_on_its_way_is_refused(procs: Procs, tmp_path: Path, ros: Any, client: Any) -> None:
    """A job text with a NUL byte: the sender's rcl cuts the string there, and
    what arrives (only its job_id) is a valid job of defaults, the 164,608
    steps of rw400 (issue 53: motion nobody asked for). With the hash of what
    was meant (``goal_sha256``) the cut text is refused and nothing moves, and
    so is a cut override; the whole goal with its right hash winds as it says."""
    from action_msgs.msg import GoalStatus

    from winder.contract.jobfile import goal_sha256

    bags = cell(procs, tmp_path, ros, client, real_time=False)
    meant = job_text(JOB, "wj")
    cut = meant.replace("    turns_per_layer", "\x00    turns_per_layer", 1)
    digest = goal_sha256(cut)
    status, result = Goal(ros, client, cut, goal_sha256=digest).result(30)
    assert status == GoalStatus.STATUS_ABORTED and not result.success, result.message
    assert result.message.startswith("job rejected: goal_sha256: the goal came as"), result.message
    # an override cut at its NUL: schedule=abort@0.5 would wind on, unaborted, as "schedule="
    override = "schedule=\x00abort@0.5"
    status, result = Goal(ros, client, meant, (override,), goal_sha256=goal_sha256(meant, [override])).result(
        30
    )
    assert status == GoalStatus.STATUS_ABORTED and "goal_sha256: the goal came as" in result.message, result
    assert not list(bags.glob("*")), "a refused goal started a run"
    # a hash that is no hash, in one line
    status, result = Goal(ros, client, meant, goal_sha256="xyz").result(30)
    assert status == GoalStatus.STATUS_ABORTED and "is not a SHA-256 in hex" in result.message, result.message
    status, result = Goal(ros, client, meant, goal_sha256=goal_sha256(meant)).result()
    assert status == GoalStatus.STATUS_SUCCEEDED, result.message
    assert result.report.steps_total == Job(**JOB, job_id="wj").total_steps


def test_a_goals_settings_end_with_its_run(procs: Procs, tmp_path: Path, ros: Any, client: Any) -> None:
    """What a goal sets is its run's, not the node's (issue 53): goal A's
    schedule aborts A, and the empty goal B after it (the settings as they
    are) winds the node's own job whole; goal C's stops that wait for a call
    (released here by ~/resume) leave goal D to run through. The node's
    parameters are what they were before the goals."""
    from action_msgs.msg import GoalStatus

    cell(procs, tmp_path, ros, client, real_time=False, **{k: v for k, v in JOB.items()}, job_id="own")
    own = Job(**JOB, job_id="own").total_steps
    status, result = Goal(ros, client, job_text(LONG, "a"), ("schedule=abort@0.5",)).result()
    assert status == GoalStatus.STATUS_ABORTED and result.report.state == "aborted", result.message
    status, result = Goal(ros, client).result()
    assert status == GoalStatus.STATUS_SUCCEEDED, result.message
    assert (result.report.job_id, result.report.steps_done, result.report.steps_total) == ("own", own, own)
    # stops that wait for ~/resume: released once here; the next goal must not meet them
    resume = Resume(ros)
    status, result = Goal(ros, client, job_text(JOB, "c"), ("stops=1:4", "stop_resume=call")).result_after(
        resume
    )
    assert status == GoalStatus.STATUS_SUCCEEDED, result.message
    status, result = Goal(ros, client, job_text(JOB, "d")).result(60)
    assert status == GoalStatus.STATUS_SUCCEEDED, result.message
    assert get_params(ros, "interp_node", ["schedule", "stops", "stop_resume", "job_id"]) == [
        "",
        "",
        "auto",
        "own",
    ]


def test_a_goals_operator_and_wire_lot_are_its_parts(
    procs: Procs, tmp_path: Path, ros: Any, client: Any
) -> None:
    """A goal's ``operator_name`` and ``wire_lot`` are its run's (issue 56):
    its job description in the bag, the bag's metadata and its part carry
    them, and the interp node's own ``operator`` (a shift's, set at start)
    is back for the next goal, which gives none; a value that is not
    printable text is refused in one line naming it, one cut at a NUL on its
    way by the goal's hash, and neither moves an axis."""
    import sqlite3

    import yaml
    from action_msgs.msg import GoalStatus

    from winder.contract.jobfile import goal_sha256

    bags = cell(procs, tmp_path, ros, client, real_time=False, operator="day-shift")
    job = job_text(JOB, "lot")
    bad = "Jane\x1b[2J"
    status, result = Goal(ros, client, job, operator_name=bad).result(30)
    assert status == GoalStatus.STATUS_ABORTED, result.message
    assert result.message.startswith(f"job rejected: operator={bad!r} is invalid: must be printable text")
    assert "\n" not in result.message
    meant = goal_sha256(job, operator="Jane\x00Doe")  # rcl cuts it to "Jane": a name nobody gave
    status, result = Goal(ros, client, job, goal_sha256=meant, operator_name="Jane\x00Doe").result(30)
    assert status == GoalStatus.STATUS_ABORTED and "goal_sha256: the goal came as" in result.message, result
    assert not list(bags.glob("*")), "a refused goal started a run"

    digest = goal_sha256(job, operator="Jane Doe", wire_lot="L-2026/7")
    given = Goal(ros, client, job, goal_sha256=digest, operator_name="Jane Doe", wire_lot="L-2026/7")
    status, result = given.result()
    assert status == GoalStatus.STATUS_SUCCEEDED, result.message
    status, plain = Goal(ros, client, job).result()  # the node's own operator, no wire lot
    assert status == GoalStatus.STATUS_SUCCEEDED, plain.message
    assert get_params(ros, "interp_node", ["operator", "wire_lot"]) == ["day-shift", ""]

    with sqlite3.connect(f"{(bags / 'parts.sqlite').as_uri()}?mode=ro", uri=True) as con:
        parts = dict(
            (part_id, (who, lot, sha))
            for part_id, who, lot, sha in con.execute(
                "SELECT part_id, operator, wire_lot, recipe_sha256 FROM parts"
            )
        )
    assert parts[result.part_id][:2] == ("Jane Doe", "L-2026/7")
    assert parts[plain.part_id][:2] == ("day-shift", None)
    assert parts[result.part_id][2] == parts[plain.part_id][2]  # one recipe, whoever wound it
    [recorded] = mcap_messages(Path(result.bag_path), "/winder/job", "winder_interfaces/msg/JobDescription")
    assert (recorded.operator_name, recorded.wire_lot) == ("Jane Doe", "L-2026/7")
    meta = yaml.safe_load((Path(result.bag_path) / "metadata.yaml").read_text())
    custom = meta["rosbag2_bagfile_information"]["custom_data"]
    assert (custom["winder_operator"], custom["winder_wire_lot"]) == ("Jane Doe", "L-2026/7")
    meta = yaml.safe_load((Path(plain.bag_path) / "metadata.yaml").read_text())
    assert "winder_wire_lot" not in meta["rosbag2_bagfile_information"]["custom_data"]


class Resume:
    """~/resume on the profile node, asked (without spinning) each time it is
    called until one answer says it resumed (a programmed stop waited for it)."""

    def __init__(self, ros: Any) -> None:
        from std_srvs.srv import Trigger

        self.client = ros.create_client(Trigger, "/profile_node/resume")
        self.asked: Any = None
        self.done = False

    def __call__(self) -> None:
        from std_srvs.srv import Trigger

        if self.asked is not None and self.asked.done():
            self.done = self.done or bool(self.asked.result().success)
            self.asked = None
        if not self.done and self.asked is None and self.client.service_is_ready():
            self.asked = self.client.call_async(Trigger.Request())
