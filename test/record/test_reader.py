"""winder.record.reader on bags written by the real nodes, cut-short bags and bad input.

Expected values come from reading the same bags with rosbags directly, and,
for cut-short files, from the byte offsets of the message records in the
complete file (found by searching for each record's bytes, built here from the
MCAP specification).

The bags are the session's (conftest's ``bag``, support.bags.CONFIGS): each
configuration of ``winder run`` runs once per session, shared by every module
that reads them.
"""

from __future__ import annotations

import json
import math
import shutil
import signal
import struct
from collections import Counter
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from conftest import Procs, final_report, rosbags_read
from mcap.reader import make_reader
from rosbags.rosbag2 import StoragePlugin
from rosbags.typesys import Stores, get_typestore
from support import wait
from support.bags import joint_arrays, rosbags_raw, step_rows, write_bag
from support.cli import assert_one_line_error, run_cli

from winder.record.reader import BagError, read_raw, read_run, recover

pytestmark = pytest.mark.ros

# -- the bags, shared by the three test modules -----------------------------------------


# -- independent reading with rosbags -------------------------------------------------------


# -- whole bags ---------------------------------------------------------------------------


def test_run_matches_rosbags(bag: Any) -> None:
    path = bag("lin2k")
    run = read_run(path)
    ref = rosbags_read(path)
    assert run.complete and run.closed and not run.recovered
    assert run.job_id == "lin2k" and run.namespace == ""
    job = ref["/winder/job"][0][1]  # a winder_interfaces/JobDescription, as rosbags reads it
    assert (job.run_id, job.job_id, job.total_steps) == (run.plan.run_id, "lin2k", run.plan.total_steps)
    assert {kv.key: kv.value for kv in job.job}["turns_per_layer"] == str(run.plan.job.turns_per_layer)
    assert [(s.kind, list(s.start), list(s.delta), s.steps) for s in job.segments] == [
        (s.kind, list(s.start), list(s.delta), s.steps) for s in run.plan.segments
    ]
    assert list(job.joint_step) == list(run.plan.joint_step)
    cfg = json.loads(ref["/winder/sim_config"][0][1].data)
    assert run.sim_config is not None
    assert run.sim_config.model == cfg["model"] == "linear"
    assert run.sim_config.publish_rate == cfg["publish_rate"] == 2000.0
    for axis in ("feed", "fork", "pole"):
        for key in ("Zr", "L", "i_a", "J", "D", "motor_step_angle", "load_torque"):
            assert getattr(run.sim_config.axes[axis], key) == cfg["axes"][axis][key]
    np.testing.assert_array_equal(run.steps, step_rows(ref["/winder/step_times"]))
    for samples, topic in ((run.states, "/winder/joint_states"), (run.commands, "/winder/joint_commands")):
        t, pos, vel = joint_arrays(ref[topic])
        np.testing.assert_array_equal(samples.t, t)
        np.testing.assert_array_equal(samples.pos, pos)
        np.testing.assert_array_equal(samples.vel, vel)
    assert {k: v for k, v in run.counts.items() if v} == {k: len(v) for k, v in ref.items()}
    final = final_report(ref)
    assert run.report == final and run.report["state"] == "done"
    # the ramp in force travels latched on winder/profile_config
    ramp = json.loads(ref["/winder/profile_config"][-1][1].data)
    assert run.profile_config == ramp
    assert run.profile == ramp["profile"] == "scurve"
    assert (ramp["v_max"], ramp["a_max"], ramp["j_max"]) == (2048.0, 8192.0, 65536.0)
    # the .mcap file and metadata.yaml name the same recording
    mcap = next(path.glob("*.mcap"))
    for other in (mcap, path / "metadata.yaml"):
        again = read_run(other)
        np.testing.assert_array_equal(again.steps, run.steps)
        assert again.complete


def test_namespaced_cell(bag: Any) -> None:
    path = bag("nlns")
    run = read_run(path)
    assert run.namespace == "/cell1"
    assert "/cell1/winder/job" in run.counts and "/winder/job" not in run.counts
    assert run.complete and run.report["state"] == "done"
    assert run.sim_config is not None and run.sim_config.axes["fork"].J == 2e-4
    assert read_run(path, namespace="cell1").steps.shape == run.steps.shape
    with pytest.raises(
        BagError, match=r"no winder job in namespace /other \(namespaces with a job: /cell1\)"
    ):
        read_run(path, namespace="/other")


def test_two_cells_in_one_bag_need_a_namespace(bag: Any, tmp_path: Path) -> None:
    store = get_typestore(Stores.ROS2_JAZZY)
    String = store.types["std_msgs/msg/String"]
    job = read_run(bag("lin2k")).plan.text
    path = tmp_path / "two"
    write_bag(
        path,
        [("/a/winder/job", "std_msgs/msg/String", 0, String(data=job)),
         ("/b/winder/job", "std_msgs/msg/String", 0, String(data=job))],
        StoragePlugin.MCAP,
    )  # fmt: skip
    with pytest.raises(BagError, match=r"2 winder cells \(/a, /b\): choose one with --namespace"):
        read_run(path)
    run = read_run(path, namespace="/b")
    assert run.namespace == "/b" and run.steps.shape == (0, 5) and not run.complete
    r = run_cli("analyze", str(path), "--namespace", "/b", "--no-plots")
    assert r.returncode == 0, r.stderr
    assert "no steps recorded" in r.stdout


def test_a_bag_of_before_the_typed_messages_reads_as_a_typed_one(tmp_path: Path) -> None:
    """Before 2026-11-28 a bag held the job description and the operator
    events as JSON in std_msgs/String; since, as winder_interfaces messages.
    The same run written both ways, each by hand here (the JSON as the
    contract gave its keys, the messages field by field), reads as the same
    plan and the same events."""
    from winder.contract.stream import describe_job
    from winder.motion.job import Job
    from winder.record.msgtypes import jazzy_store

    run_id = "old_20261127_101010123_1"
    text = describe_job(
        Job.from_dict({"job_id": "old", "turns_per_layer": 3, "poles": 2}), run_id, stops=[(0, 2)]
    )
    doc = json.loads(text)
    events = [
        {"event": "pause", "source": "call", "run_id": run_id, "job_id": "old", "t_ns": 100,
         "t_request_ns": 90, "latency_ns": 10, "t_rest_ns": 150, "steps": 7, "segment": 0, "step": 7,
         "v": 10.0, "a": -2.0, "stop_distance": 1.5},
        {"event": "resume", "source": "call", "run_id": run_id, "t_ns": 400, "steps": 7},
        {"event": "override", "source": "schedule", "run_id": run_id, "t_ns": 500, "factor": 0.5,
         "v_max": 1024.0, "note": "applied"},
        {"event": "abort", "run_id": "another_20261127_101010123_2", "t_ns": 1, "t_rest_ns": 1, "steps": 0},
        {"event": "pause", "run_id": run_id, "t_ns": 600},  # names no steps: no event the consumer took
    ]  # fmt: skip
    store = jazzy_store()
    types = store.types
    String, KeyValue = types["std_msgs/msg/String"], types["diagnostic_msgs/msg/KeyValue"]
    Description, Segment = (
        types["winder_interfaces/msg/JobDescription"],
        types["winder_interfaces/msg/JobSegment"],
    )
    Stop, Event = types["winder_interfaces/msg/JobStop"], types["winder_interfaces/msg/ControlEvent"]

    def pairs(values: dict[str, Any]) -> list[Any]:
        return [KeyValue(key=k, value=v if isinstance(v, str) else json.dumps(v)) for k, v in values.items()]

    typed_job = Description(
        format="winder.job/1", run_id=run_id, job_id="old", job=pairs(doc["job"]), has_ramp=False, ramp=[],
        stops=[Stop(segment=0, step=2)], stop_pause=0.0, stop_resume="auto", schedule="", job_file_sha256="",
        operator_name="", wire_lot="", source_bag="", source_run_id="", axes=["feed", "fork", "pole"],
        joint_step=np.array(doc["joint_step"]), step_lengths=np.array(doc["step_lengths"]),
        total_steps=doc["total_steps"],
        segments=[
            Segment(kind=s["kind"], start=np.array(s["start"], np.int64),
                    delta=np.array(s["delta"], np.int64), steps=s["steps"], pole=s["pole"], layer=s["layer"])
            for s in doc["segments"]
        ],
    )  # fmt: skip
    said = {"t_rest_ns": -1, "steps": -1, "t_request_ns": -1, "latency_ns": -1, "segment": -1, "step": 0}
    unsaid = {k: math.nan for k in ("factor", "v", "a", "stop_distance", "v_max")}
    typed_events = [Event(**{"source": "", "job_id": "", "note": "", **said, **unsaid, **e}) for e in events]
    old, new = tmp_path / "old", tmp_path / "new"
    write_bag(
        old,
        [("/winder/job", "std_msgs/msg/String", 0, String(data=text)),
         *(("/winder/control", "std_msgs/msg/String", i + 1, String(data=json.dumps(e)))
           for i, e in enumerate(events))],
        StoragePlugin.MCAP,
    )  # fmt: skip
    write_bag(
        new,
        [("/winder/job", "winder_interfaces/msg/JobDescription", 0, typed_job),
         *(("/winder/control", "winder_interfaces/msg/ControlEvent", i + 1, e)
           for i, e in enumerate(typed_events))],
        StoragePlugin.MCAP,
    )  # fmt: skip
    before, since = read_run(old), read_run(new)
    assert since.plan == before.plan and since.plan.text == text
    assert since.plan.stops == ((0, 2),) and since.plan.run_id == run_id
    # the other run's abort, and the pause that is no event, left out of both
    assert list(since.events) == list(before.events) == events[:3]

    # another type on the cell's topics: no events; no job description, said in one line
    other = tmp_path / "other"
    write_bag(
        other,
        [("/winder/job", "winder_interfaces/msg/JobDescription", 0, typed_job),
         ("/winder/control", "diagnostic_msgs/msg/KeyValue", 1, KeyValue(key="event", value="abort"))],
        StoragePlugin.MCAP,
    )  # fmt: skip
    assert read_run(other).events == ()
    wrong = tmp_path / "wrong"
    write_bag(wrong, [("/winder/job", "diagnostic_msgs/msg/KeyValue", 0, KeyValue(key="a", value="b"))],
              StoragePlugin.MCAP)  # fmt: skip
    with pytest.raises(BagError, match=r"^[^\n]*/winder/job: [^\n]*$"):
        read_run(wrong)


#: winder_interfaces/msg/JobDescription as winder recorded it from 2026-11-28 until the run's
#: operator and wire lot (operator_name, wire_lot after job_file_sha256) joined it
JOB_DESCRIPTION_20261128 = (
    "string FORMAT=winder.job/1\nstring format\nstring run_id\nstring job_id\n"
    "diagnostic_msgs/KeyValue[] job\n"
    "bool has_ramp\ndiagnostic_msgs/KeyValue[] ramp\nJobStop[] stops\nfloat64 stop_pause\n"
    "string stop_resume\nstring schedule\nstring job_file_sha256\nstring source_bag\n"
    "string source_run_id\nstring[] axes\nfloat64[] joint_step\nfloat64[] step_lengths\n"
    "uint64 total_steps\nJobSegment[] segments"
)


def test_a_bag_of_before_the_operator_reads_with_the_definition_it_holds(tmp_path: Path) -> None:
    """A JobDescription recorded before ``operator_name`` and ``wire_lot``
    were its fields: CDR has no field names, so today's definition cannot
    decode it (the bytes end before its fields do). The reader decodes it
    with the definition the bag holds: the plan as it was, no operator; and
    ``winder bag recover`` writes its copy with that definition too."""
    from rosbags.rosbag2 import Writer
    from rosbags.typesys import get_types_from_msg

    from winder.contract.stream import describe_job
    from winder.motion.job import Job
    from winder.record.msgtypes import DEFINITIONS

    run_id = "old_20261128_101010123_1"
    text = describe_job(Job.from_dict({"job_id": "old", "turns_per_layer": 3, "poles": 2}), run_id)
    doc = json.loads(text)
    store = get_typestore(Stores.ROS2_JAZZY)  # the types as that winder defined them
    for name, definition in DEFINITIONS.items():
        if name.startswith("winder_interfaces/"):
            old_def = JOB_DESCRIPTION_20261128 if name.endswith("/JobDescription") else definition
            store.register(get_types_from_msg(old_def, name))
    types = store.types
    KeyValue, Segment = types["diagnostic_msgs/msg/KeyValue"], types["winder_interfaces/msg/JobSegment"]
    msg = types["winder_interfaces/msg/JobDescription"](
        format="winder.job/1", run_id=run_id, job_id="old",
        job=[KeyValue(key=k, value=v if isinstance(v, str) else json.dumps(v))
             for k, v in doc["job"].items()],
        has_ramp=False, ramp=[], stops=[], stop_pause=0.0, stop_resume="auto", schedule="",
        job_file_sha256="", source_bag="", source_run_id="", axes=["feed", "fork", "pole"],
        joint_step=np.array(doc["joint_step"]), step_lengths=np.array(doc["step_lengths"]),
        total_steps=doc["total_steps"],
        segments=[
            Segment(kind=s["kind"], start=np.array(s["start"], np.int64),
                    delta=np.array(s["delta"], np.int64), steps=s["steps"], pole=s["pole"], layer=s["layer"])
            for s in doc["segments"]
        ],
    )  # fmt: skip
    path = tmp_path / "before_operator"
    with Writer(path, version=9, storage_plugin=StoragePlugin.MCAP) as w:
        conn = w.add_connection("/winder/job", "winder_interfaces/msg/JobDescription", typestore=store)
        w.write(conn, 0, store.serialize_cdr(msg, "winder_interfaces/msg/JobDescription"))
    run = read_run(path)
    assert json.loads(run.plan.text) == doc  # run facts not given are not in the text
    assert (run.plan.run_id, run.plan.total_steps, run.plan.operator, run.plan.wire_lot) == (
        run_id,
        doc["total_steps"],
        "",
        "",
    )
    copy, saved = recover(path, tmp_path / "copy")
    assert saved == 1 and read_run(copy).plan == run.plan


# -- cut-short files ------------------------------------------------------------------------


def record_ends(data: bytes, messages: list[tuple[str, int, bytes]]) -> list[int]:
    """Byte offset just past each message's MCAP record in the complete file.

    A message record is opcode 0x05, u64 length, then u16 channel, u32
    sequence, u64 log time, u64 publish time and the data (the MCAP spec);
    rosbags writes sequence 0 and publish time = log time."""
    ends = []
    used: set[int] = set()
    last = 0
    for _, t, payload in messages:
        body = struct.pack("<IQQ", 0, t, t) + payload
        # messages come in time order, which is nearly file order: look near the last one first
        for start in (max(0, last - 100_000), 0):
            at = data.find(body, start)
            while at >= 0:
                rec = at - 2 - 9
                length = struct.unpack_from("<Q", data, rec + 1)[0]
                if data[rec] == 0x05 and length == 22 + len(payload) and rec not in used:
                    break
                at = data.find(body, at + 1)
            if at >= 0:
                break
        assert at >= 0, "record not found"
        used.add(rec)
        ends.append(rec + 9 + length)
        last = rec
    return ends


def top_level_records(data: bytes) -> list[tuple[int, int, int]]:
    """(opcode, start, end) of each top-level record: magic, then records of
    opcode (u8), length (u64), body, up to the footer (opcode 0x02)."""
    out = []
    pos = 8
    while pos + 9 <= len(data):
        op = data[pos]
        end = pos + 9 + struct.unpack_from("<Q", data, pos + 1)[0]
        out.append((op, pos, end))
        if op == 0x02:
            break
        pos = end
    return out


def test_cut_short_files_recover_every_whole_message(bag: Any, tmp_path: Path) -> None:
    src = bag("lin2k")
    mcap = next(src.glob("*.mcap"))
    data = mcap.read_bytes()
    full = rosbags_raw(src)
    ends = np.array(record_ends(data, full))
    order = np.argsort(ends)
    size = len(data)
    chunks = [(start, end) for op, start, end in top_level_records(data) if op == 0x06]
    assert len(chunks) >= 3
    first_chunk_end = chunks[0][1]
    cuts = {
        "inside the first chunk": int(ends[order[50]]) + 7,
        "inside a later chunk": (chunks[1][0] + chunks[1][1]) // 2,
        "at the end of the first chunk's data": first_chunk_end,
        "one byte short of a message": int(ends[order[len(order) // 2]]) - 1,
        "right after a message": int(ends[order[len(order) // 2]]),
        "in the summary section": size - 200,
        "one byte short of the end": size - 1,
    }
    for what, cut in cuts.items():
        d = tmp_path / f"cut_{cut}"
        d.mkdir()
        (d / mcap.name).write_bytes(data[:cut])
        expected = Counter((full[i][0], full[i][1], full[i][2]) for i in np.nonzero(ends <= cut)[0])
        raw = read_raw(d)
        got = Counter((raw.connections[c].topic, t, bytes(p)) for c, t, p in raw.messages)
        assert got == expected, what
        assert raw.recovered and not raw.closed, what
        run = read_run(d)
        assert not run.complete and run.recovered, what
        rows = run.steps
        # the step rows that survived are the head of the stream, each one step on
        assert np.all(np.abs(np.diff(rows[:, 2:], axis=0)) <= 1), what
        out, saved = recover(d)
        assert out == d.with_name(d.name + "_recovered")
        assert saved == sum(expected.values())
        again = Counter(rosbags_raw(out))
        assert again == expected, what
        assert read_run(out).closed
    with pytest.raises(BagError, match="damaged beyond recovery"):
        cut = tmp_path / "too_short"
        cut.mkdir()
        (cut / "x.mcap").write_bytes(data[:100])
        read_raw(cut)


def test_sigkilled_sim_node_leaves_a_bag_that_reads_and_recovers(procs: Procs, tmp_path: Path) -> None:
    bag_dir = tmp_path / "bags"
    sim = procs.start("sim_node", "-p", f"bag_dir:={bag_dir}")
    procs.start("profile_node")
    procs.start("interp_node")  # the default job, started as soon as the chain is connected

    def past_60_percent() -> Path | None:
        # the step stream is recorded first, joint states follow: the whole job is 13.5 MB
        # of messages in 4.4 MB of lz4 chunks; kill the sim node past 60 % of that
        # (a bag opens in a hidden directory renamed once set up: a file listed may be gone)
        try:
            found = list(bag_dir.glob("*/*.mcap"))
            return found[0] if found and found[0].stat().st_size > 2_700_000 else None
        except FileNotFoundError:
            return None

    mcap = wait.until(
        past_60_percent,
        60,
        "the sim node's bag past 2.7 MB",
        heard=lambda: (
            [(str(f.relative_to(bag_dir)), f.stat().st_size) for f in bag_dir.glob("*/*.mcap")],
            procs.log(sim)[-1000:],
        ),
        poll=0.002,  # the job ends soon after: looked at often, to kill it before its end
        running=sim,
    )
    sim.send_signal(signal.SIGKILL)
    sim.wait(timeout=10)
    path = mcap.parent
    # the metadata is there from the bag's open on, and says the bag was never closed
    assert "winder_bag: recording" in (path / "metadata.yaml").read_text()
    # every reader opens it as it is, and reads the same messages: rosbags (with the
    # directory's metadata.yaml), the mcap library and winder's reader
    ros = rosbags_raw(path)
    with mcap.open("rb") as f:
        lib = [(ch.topic, m.log_time, bytes(m.data)) for _, ch, m in make_reader(f).iter_messages()]
    raw = read_raw(path)
    own = [(raw.connections[cid].topic, t, bytes(d)) for cid, t, d in raw.messages]
    assert own == lib == ros and len(own) > 1000
    run = read_run(path)
    assert run.recovered and not run.complete and not run.closed
    assert 0 < run.steps.shape[0] <= run.plan.total_steps
    assert run.report.get("state") != "done"  # the final report never reached the file
    steps = np.diff(np.vstack([run.plan.segments[0].start, run.steps[:, 2:]]), axis=0)
    assert np.all(np.abs(steps) <= 1) and np.all(np.any(steps != 0, axis=1))
    assert np.all(np.diff(run.states.t) > 0) and len(run.states) > 100
    r = run_cli("bag", "recover", str(path))
    assert r.returncode == 0, r.stderr
    saved = int(r.stdout.split("recovered ")[1].split()[0])
    out = path.with_name(path.name + "_recovered")
    assert sum(Counter(t for t, _, _ in rosbags_raw(out)).values()) == saved
    assert saved == sum(read_run(path).counts.values())
    a = run_cli("analyze", str(path), "--no-plots")
    assert a.returncode == 0, a.stderr
    assert "cut short (recovered)" in a.stdout
    again = run_cli("bag", "recover", str(path))
    assert_one_line_error(again, "already exists")


# -- bad input ----------------------------------------------------------------------------


def test_bad_bags_are_one_line_errors(tmp_path: Path, bag: Any) -> None:
    store = get_typestore(Stores.ROS2_JAZZY)
    String = store.types["std_msgs/msg/String"]
    rng = np.random.default_rng(1)
    empty = tmp_path / "empty"
    empty.mkdir()
    noise_dir = tmp_path / "noise"
    noise_dir.mkdir()
    (noise_dir / "noise.mcap").write_bytes(rng.bytes(4096))
    noise_file = tmp_path / "noise.bin"
    noise_file.write_bytes(rng.bytes(4096))
    magic_then_noise = tmp_path / "magic.mcap"
    magic_then_noise.write_bytes(b"\x89MCAP0\r\n" + rng.bytes(4096))
    chatter = tmp_path / "chatter"
    write_bag(chatter, [("/chatter", "std_msgs/msg/String", i, String(data=f"hi {i}")) for i in range(3)],
               StoragePlugin.MCAP)  # fmt: skip
    chatter_db = tmp_path / "chatter_db"
    write_bag(chatter_db, [("/chatter", "std_msgs/msg/String", 1, String(data="hi"))], StoragePlugin.SQLITE3)
    silent = tmp_path / "silent"
    write_bag(silent, [], StoragePlugin.MCAP)
    meta_only = tmp_path / "meta_only"
    meta_only.mkdir()
    shutil.copy(bag("lin2k") / "metadata.yaml", meta_only / "metadata.yaml")
    cases = [
        (tmp_path / "missing", "no such file or directory"),
        (empty, "empty directory, not a rosbag2 recording"),
        (noise_dir, "not an MCAP file"),
        (noise_file, "not an MCAP file"),
        (magic_then_noise, "damaged beyond recovery"),
        (chatter, "not a winder bag: no /winder/job topic"),
        (chatter_db, "not a winder bag: no /winder/job topic"),
        (meta_only, "metadata.yaml lists no MCAP file that exists here"),
    ]
    for path, why in cases:
        for command in ("analyze", "identify"):
            assert_one_line_error(run_cli(command, str(path), "--no-plots"), str(path), why)
    assert_one_line_error(run_cli("analyze", str(silent), "--no-plots"), "empty recording: no messages")
    assert_one_line_error(run_cli("bag", "recover", str(noise_file)), "not an MCAP file")
    ok = run_cli("bag", "recover", str(bag("lin2k")))
    assert ok.returncode == 0 and "nothing to recover" in ok.stdout


def test_the_reader_never_opens_a_file_outside_the_bag(bag: Any, tmp_path: Path) -> None:
    """metadata.yaml naming ``../x``, an absolute path, or a file that is a
    symlink out of the directory: refused in one line naming the path, by the
    reader and by every command that reads a bag; nothing outside is read."""
    src = bag("lin2k")
    mcap = next(src.glob("*.mcap"))
    outside = tmp_path / "outside"
    outside.mkdir()
    shutil.copy(mcap, outside / "elsewhere.mcap")  # a readable bag file, just not this bag's
    text = (src / "metadata.yaml").read_text()
    cases: dict[str, tuple[Path, str]] = {}

    def listing(name: str, listed: str) -> Path:
        d = tmp_path / name
        d.mkdir()
        shutil.copy(mcap, d / mcap.name)
        (d / "metadata.yaml").write_text(text.replace(mcap.name, listed))
        return d

    cases["dotdot"] = (listing("dotdot", "../outside/elsewhere.mcap"), "'../outside/elsewhere.mcap'")
    absolute = str(outside / "elsewhere.mcap")
    cases["absolute"] = (listing("absolute", absolute), repr(absolute))
    link = listing("link", "link.mcap")
    (link / "link.mcap").symlink_to(outside / "elsewhere.mcap")
    cases["listed symlink"] = (link, "link.mcap")
    unlisted = tmp_path / "unlisted"
    unlisted.mkdir()
    (unlisted / "x.mcap").symlink_to(outside / "elsewhere.mcap")  # no metadata: found by its suffix
    cases["unlisted symlink"] = (unlisted, "x.mcap")
    meta_link = tmp_path / "meta_link"
    meta_link.mkdir()
    shutil.copy(mcap, meta_link / mcap.name)
    (outside / "metadata.yaml").write_text(text)
    (meta_link / "metadata.yaml").symlink_to(outside / "metadata.yaml")
    cases["metadata symlink"] = (meta_link, "metadata.yaml")
    for what, (path, needle) in cases.items():
        with pytest.raises(BagError) as err:
            read_raw(path)
        msg = str(err.value)
        assert "\n" not in msg and needle in msg and "outside the bag's directory" in msg, (what, msg)
        for command in (["analyze", "--no-plots"], ["bag", "recover"], ["play"], ["export"]):
            r = run_cli(command[0], *command[1:], str(path))
            assert_one_line_error(r, needle, "outside the bag's directory")
    assert not list(tmp_path.glob("*_recovered")) and not list(tmp_path.glob("*_csv"))
