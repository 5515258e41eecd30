"""What the README and docs/ say of the code, checked against the code: each
claim's truth is taken from where the code keeps it, never retyped here, so a
change to the code that leaves a sentence behind fails here, not in a
reader's hands (issue 54: the docs had drifted from the code in a dozen
places).

* CONTRACT.md §3.1 lists every field a job description's ``job`` may hold,
  with its type and unit, and which of them go out only when set
  (``FIELD_SPECS``, ``stream.LATER_FIELDS``); OPERATING.md's job table too;
* the QoS that CONTRACT.md §2 and INTEGRATING.md give each topic is what the
  cell's writers offer (``winder.contract.qos``, and the statuses' own writer
  on ``/diagnostics``), every topic of the cell is in both tables, and §2's
  "bag" column names what the sim node records;
* the type each table gives a topic is the code's, and the README,
  INTEGRATING.md and CONTRACT.md name exactly the topics whose types are
  ``winder_interfaces``' (no "standard message types only");
* INTEGRATING.md's conformance command selects the reader's own consumer
  alone, and the defaults it states (the ROS domains, ``settle_time``,
  ``position_tolerance``, ``paces``) are the code's;
* the default job's numbers that ANALYSIS.md and the README show are what a
  run of it and ``winder analyze`` print now (a node test).

What a test cannot check is kept from claiming more than was measured: the
mypy file count is not written down, and the README's sizes and times and
OPERATING.md's time of a ``winder ctl`` command say when and how they were
measured (they vary with the machine; no test times anything).
"""

from __future__ import annotations

import os
import re
import shlex
import subprocess
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from conftest import BIN, next_domain, release_domain
from support.paths import ROOT

from winder.contract.qos import TOPIC_QOS, Qos
from winder.contract.stream import LATER_FIELDS
from winder.contract.topics import TOPIC_DIAGNOSTICS
from winder.motion.job import AUTO, FIELD_SPECS
from winder.record.bag import bags_in
from winder.spec import Spec, SpecError

README = ROOT / "README.md"
CONTRACT = ROOT / "docs" / "CONTRACT.md"
INTEGRATING = ROOT / "docs" / "INTEGRATING.md"
OPERATING = ROOT / "docs" / "OPERATING.md"
ANALYSIS = ROOT / "docs" / "ANALYSIS.md"
DOCS = [README, *sorted((ROOT / "docs").glob("*.md"))]


# -- reading Markdown --------------------------------------------------------
def section(path: Path, heading: str) -> str:
    """The text under the heading that starts with ``heading``, to the next
    heading of the same or a higher level (fenced blocks are not headings)."""
    lines = path.read_text().splitlines()
    fenced, start, level = False, -1, 0
    out: list[str] = []
    for line in lines:
        if line.lstrip().startswith("```"):
            fenced = not fenced
        m = None if fenced else re.match(r"^(#+) (.*)$", line)
        if start >= 0:
            if m and len(m.group(1)) <= level:
                break
            out.append(line)
        elif m and m.group(2).startswith(heading):
            start, level = 1, len(m.group(1))
    assert start >= 0, f"{path.name} has no heading {heading!r}"
    return "\n".join(out)


def cells(row: str) -> list[str]:
    """The cells of a Markdown table row (``|`` inside code spans kept)."""
    out, cur, code = [], "", False
    for ch in row.strip().strip("|"):
        if ch == "`":
            code = not code
        if ch == "|" and not code and not cur.endswith("\\"):
            out.append(cur.strip())
            cur = ""
        else:
            cur += ch
    return [*out, cur.strip()]


def table(text: str, header: str) -> list[list[str]]:
    """The rows (as cells) of the table whose header row starts with ``header``."""
    lines = text.splitlines()
    start = next((i for i, line in enumerate(lines) if line.startswith(header)), None)
    assert start is not None, f"no table with the header {header!r}"
    rows = []
    for line in lines[start + 2 :]:
        if not line.startswith("|"):
            break
        rows.append(cells(line))
    assert rows, f"the table {header!r} has no rows"
    return rows


def names(cell: str) -> list[str]:
    """The backquoted words of a cell."""
    return re.findall(r"`([^`]+)`", cell)


def fenced_after(path: Path, anchor: str) -> list[str]:
    """The lines of the first fenced block after the line holding ``anchor``."""
    lines = path.read_text().splitlines()
    at = next((i for i, line in enumerate(lines) if anchor in line), None)
    assert at is not None, f"{path.name}: no line holds {anchor!r}"
    start = next(i for i in range(at + 1, len(lines)) if lines[i].startswith("```"))
    end = next(i for i in range(start + 1, len(lines)) if lines[i].startswith("```"))
    return lines[start + 1 : end]


def prose(path: Path) -> str:
    """A document without its fenced blocks."""
    return re.sub(r"^```.*?^```", "", path.read_text(), flags=re.S | re.M)


# -- the job's fields ----------------------------------------------------------
#: the type column's word for each kind of setting
KIND_WORDS = {str: "string", float: "number", int: "integer", bool: "bool"}


def job_fields() -> dict[str, list[str]]:
    """CONTRACT.md's table of the job fields: field -> its cells after the name."""
    rows = table(section(CONTRACT, "The job fields"), "| field | type | unit | written |")
    out: dict[str, list[str]] = {}
    for row in rows:
        [name] = names(row[0])
        assert name not in out, f"CONTRACT.md lists the job field {name} twice"
        out[name] = row[1:]
    return out


def test_the_contract_lists_every_job_field_the_parser_takes() -> None:
    """A description's ``job`` holds any field of ``FIELD_SPECS`` and no
    other (``Job.from_dict`` refuses the rest): the contract lists them all,
    and no field the parser does not take."""
    listed = set(job_fields())
    assert listed == set(FIELD_SPECS), (
        f"missing from CONTRACT.md: {sorted(set(FIELD_SPECS) - listed)}; "
        f"listed but not taken: {sorted(listed - set(FIELD_SPECS))}"
    )


def takes_auto(spec: Spec) -> bool:
    """Whether a number setting also takes the word ``auto`` (``turns_per_layer``)."""
    if spec.kind is str:
        return False
    try:
        return bool(spec.parse(AUTO) == AUTO)
    except SpecError:
        return False


def test_each_job_fields_type_unit_and_choices_are_the_codes() -> None:
    """Each row's type and unit are its spec's, and a field of choices names
    every choice (a bool once read "times `tension.derate`")."""
    bad = []
    for name, (kind, unit, _written, meaning) in job_fields().items():
        spec = FIELD_SPECS[name]
        want = KIND_WORDS[spec.kind] + (f" or `{AUTO}`" if takes_auto(spec) else "")
        if kind != want:
            bad.append(f"{name}: type {kind!r}, the code's is {want!r}")
        if unit != (spec.unit or "—"):
            bad.append(f"{name}: unit {unit!r}, the code's is {spec.unit or '—'!r}")
        missing = [c for c in spec.choices if f"`{c}`" not in meaning]
        if missing:
            bad.append(f"{name}: its choices {missing} are not named")
    assert not bad, "\n".join(bad)


def test_the_fields_written_only_when_set_are_the_codes() -> None:
    """``written``: ``when set`` exactly for the fields ``describe_job``
    leaves out at their default (``stream.LATER_FIELDS``)."""
    later = {name for name, row in job_fields().items() if row[2].startswith("when set")}
    always = {name for name, row in job_fields().items() if row[2] == "always"}
    assert later == set(LATER_FIELDS), (sorted(later ^ set(LATER_FIELDS)),)
    assert always == set(FIELD_SPECS) - set(LATER_FIELDS)


def test_operating_lists_every_job_field() -> None:
    """OPERATING.md's job table (the ranges and defaults the contract points
    to) names every field, and no other."""
    rows = table(section(OPERATING, "Winding jobs"), "| field | default | range |")
    listed = {n for row in rows for n in names(row[0])}
    assert listed == set(FIELD_SPECS), (sorted(listed ^ set(FIELD_SPECS)),)


# -- topics: QoS and types ------------------------------------------------------
def offered() -> dict[str, str]:
    """What the cell's writers offer on each topic, in the words of
    :meth:`Qos.describe`: the contract's table, but on ``/diagnostics`` the
    statuses' own writer (``winder.ros.diagnostics``), which keeps them."""
    from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

    from winder.ros.diagnostics import QOS_DIAGNOSTICS_KEPT
    from winder.ros.qos import profile

    def words(q: QoSProfile) -> str:
        return Qos(
            reliable=q.reliability == ReliabilityPolicy.RELIABLE,
            transient_local=q.durability == DurabilityPolicy.TRANSIENT_LOCAL,
            keep_all=q.history == HistoryPolicy.KEEP_ALL,
            depth=q.depth,
        ).describe()

    out = {topic: words(profile(q)) for topic, q in TOPIC_QOS.items()}
    out[TOPIC_DIAGNOSTICS] = words(QOS_DIAGNOSTICS_KEPT)
    return out


def topic_rows(path: Path, text: str) -> dict[str, list[str]]:
    """A topic table: topic (its first backquoted name) -> the cells after it."""
    rows = table(text, "| topic | type | QoS |")
    out = {names(row[0])[0]: row[1:] for row in rows}
    assert len(out) == len(rows), f"{path.name}: a topic listed twice"
    return out


def test_the_contract_gives_each_topic_the_qos_its_writer_offers() -> None:
    """CONTRACT.md §2 names a profile per topic and defines each profile in
    words: the profile's words are what the topic's writer offers."""
    text = section(CONTRACT, "2. Topics and services")
    defined = {m.group(1): " ".join(m.group(2).split()) for m in re.finditer(r"\*(\w+)\* = ([^;.(]+)", text)}
    rows = topic_rows(CONTRACT, text)
    assert set(rows) == set(TOPIC_QOS), f"CONTRACT.md §2: {sorted(set(rows) ^ set(TOPIC_QOS))}"
    truth = offered()
    bad = [
        f"{topic}: *{row[1]}* = {defined.get(row[1])!r}, its writer offers {truth[topic]!r}"
        for topic, row in rows.items()
        if defined.get(row[1]) != truth[topic]
    ]
    assert not bad, "\n".join(bad)


def test_integrating_gives_each_topic_the_qos_its_writer_offers() -> None:
    """INTEGRATING.md's topic table says each topic's QoS in the same words
    (what follows in parentheses explains them), for every topic of the cell."""
    rows = topic_rows(INTEGRATING, section(INTEGRATING, "Topic contract"))
    assert set(rows) == set(TOPIC_QOS), f"INTEGRATING.md: {sorted(set(rows) ^ set(TOPIC_QOS))}"
    truth = offered()
    bad = [
        f"{topic}: {row[1]!r}, its writer offers {truth[topic]!r}"
        for topic, row in rows.items()
        if row[1].split(" (")[0] != truth[topic]
    ]
    assert not bad, "\n".join(bad)


def recorded() -> list[tuple[str, str]]:
    """The topics the sim node records, with their types: every consumer's and its own."""
    from winder_sim.sim_node import SIM_TOPICS

    from winder.ros.consumer import CONSUMER_TOPICS

    return [*CONSUMER_TOPICS.values(), *SIM_TOPICS.values()]


def code_types() -> dict[str, str]:
    """The type of each topic where the code names it (``package/Name``): the
    topics the sim node records, and the topics a live view serves."""
    from winder.ros.view import VIEW_TOPICS

    pairs = [*recorded(), *((t.name, t.msgtype) for t in VIEW_TOPICS)]
    out: dict[str, str] = {}
    for topic, msgtype in pairs:
        short = msgtype.replace("/msg/", "/")
        assert out.setdefault(topic, short) == short, f"the code gives {topic} two types"
    return out


def test_the_tables_give_each_topic_the_codes_type() -> None:
    truth = code_types()
    for path, text in (
        (CONTRACT, section(CONTRACT, "2. Topics and services")),
        (INTEGRATING, section(INTEGRATING, "Topic contract")),
    ):
        rows = topic_rows(path, text)
        bad = [
            f"{path.name}: {topic}: {row[0]}, the code's {truth[topic]}"
            for topic, row in rows.items()
            if topic in truth and names(row[0])[0] != truth[topic]
        ]
        assert not bad, "\n".join(bad)


def test_the_contract_says_which_topics_the_sim_nodes_bag_holds() -> None:
    """§2's "bag" column: yes for exactly the topics the sim node records."""
    rows = topic_rows(CONTRACT, section(CONTRACT, "2. Topics and services"))
    said = {topic for topic, row in rows.items() if row[-1].startswith("yes")}
    assert said == {topic for topic, _ in recorded()}, sorted(said ^ {topic for topic, _ in recorded()})


def test_the_docs_name_the_topics_that_need_winder_interfaces() -> None:
    """The claim "standard message types only" was false once winder/job, winder/state,
    winder/control and winder/report became ``winder_interfaces`` types: the
    README, INTEGRATING.md and CONTRACT.md each name exactly those topics as
    the ones a reader needs ``winder_interfaces`` for, and no document says
    the cell's types are standard only."""
    own = {t for t, msgtype in code_types().items() if msgtype.startswith("winder_interfaces/")}
    assert own, "the code names no topic of a winder_interfaces type"
    for path in (README, INTEGRATING, CONTRACT):
        text = " ".join(prose(path).split())
        m = re.search(r"every topic (?:and service )?but (.*?), which are `winder_interfaces` types", text)
        assert m, f"{path.name} does not say which topics are of winder_interfaces types"
        assert set(names(m.group(1))) == own, (path.name, sorted(own))
    for path in DOCS:
        text = " ".join(prose(path).split()).lower()
        assert "types only" not in text, f"{path.name} says the cell's types are standard only"


# -- the conformance suite, as INTEGRATING.md tells a driver author --------------
def integrating_conformance() -> tuple[dict[str, str], list[str], str]:
    """INTEGRATING.md's conformance command (its variables, its argv) and the
    text that explains it."""
    text = INTEGRATING.read_text()
    m = re.search(r"```sh\n(WINDER_CONSUMER=.*?test_conformance\.py.*?)\n```\n(.*?)\n(?=\*\*)", text, re.S)
    assert m, "INTEGRATING.md shows no conformance command"
    words = shlex.split(m.group(1))
    env = dict(w.split("=", 1) for w in words if re.match(r"^[A-Z_]+=", w))
    argv = [w for w in words if not re.match(r"^[A-Z_]+=", w)]
    return env, argv, " ".join(m.group(2).split())


def collected(env: dict[str, str], argv: list[str]) -> set[str]:
    """The test ids pytest collects for ``argv`` (run in the repository's root)."""
    assert argv[0] == ".venv/bin/python" and argv[1:3] == ["-m", "pytest"], argv
    r = subprocess.run(
        [str(BIN / "python"), *argv[1:], "--collect-only", "-q", "-p", "no:cacheprovider"],
        cwd=ROOT,
        env={**os.environ, **env},
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert r.returncode == 0, r.stdout + r.stderr
    return {line for line in r.stdout.splitlines() if "::" in line}


def test_the_conformance_command_selects_the_readers_consumer_alone() -> None:
    """The command, as shown, collects the tests of the consumer it names
    (``WINDER_CONSUMER``) and none of the stock subjects' tests."""
    env, argv, _ = integrating_conformance()
    assert "WINDER_CONSUMER" in env, env
    everything = collected(env, [a for i, a in enumerate(argv) if a != "-k" and argv[i - 1] != "-k"])
    mine = {t for t in everything if t.endswith("[WINDER_CONSUMER]")}
    assert mine and everything - mine, "the suite has no test of the named consumer, or no other"
    assert collected(env, argv) == mine


def test_what_the_conformance_text_says_of_a_driver_is_the_codes(monkeypatch: pytest.MonkeyPatch) -> None:
    """The ROS domains the suite takes unless told, and a driver's
    ``settle_time`` and ``position_tolerance`` defaults and ``paces``, as
    INTEGRATING.md states them, are the code's."""
    from support import domains

    from winder.ros.driver import DRIVER_SPECS, Backend

    _, _, text = integrating_conformance()
    monkeypatch.delenv("WINDER_TEST_DOMAINS", raising=False)
    pool = domains._pool()
    m = re.search(r"`WINDER_TEST_DOMAINS` \(`(\d+)-(\d+)` unless set", text)
    assert m and (int(m.group(1)), int(m.group(2))) == (pool.start, pool.stop - 1), (m and m.groups(), pool)
    m = re.search(r"`settle_time` \(its setting, ([\d.]+) s by default\)", text)
    assert m and float(m.group(1)) == DRIVER_SPECS["settle_time"].default, m and m.group(0)
    m = re.search(r"`position_tolerance`\s+\(([\d.]+) steps? by default\)", text)
    assert m and float(m.group(1)) == DRIVER_SPECS["position_tolerance"].default, m and m.group(0)
    m = re.search(r"`in_position_timeout` \(([\d.]+) s by default\)", text)
    assert m and float(m.group(1)) == DRIVER_SPECS["in_position_timeout"].default, m and m.group(0)

    class Quiet(Backend):  # only what a Backend needs: paces is its default
        def begin(self, run: Any) -> dict[str, object]:
            return {}

        def write(self, t_ns: int, rows: Any) -> None:
            return None

        def read(self, t_ns: int) -> Any:
            return np.zeros(3)

    assert "`Backend.paces()` returns True (the default)" in text
    assert Quiet().paces({}) is True


# -- what is not checked is not claimed ----------------------------------------------
def test_the_mypy_file_count_is_not_written_down() -> None:
    """mypy's count of the files it checked changes with every module
    added (the README said 131 when it was 134): the docs show it as N."""
    for path in DOCS:
        found = re.findall(r"found in \d+ source files", " ".join(path.read_text().split()))
        assert not found, f"{path.name}: {found}"


def test_the_readmes_sizes_and_times_say_when_they_were_measured() -> None:
    """A size or a time of the install is a measurement of one machine on one
    day: a paragraph of the README that gives one says when and how it was
    measured (no test times anything)."""
    text = re.sub(r"<!--.*?-->", "", prose(README), flags=re.S)
    for para in re.split(r"\n\s*\n", text):
        flat = " ".join(para.split())
        if re.search(r"\d+ [MG]B\b", flat) or ("install" in flat and re.search(r"\d+ (?:s|min)\b", flat)):
            assert re.search(r"[Mm]easured .*\d{4}-\d{2}-\d{2}", flat), flat


def test_the_time_of_a_ctl_command_says_when_it_was_measured() -> None:
    """OPERATING.md's time for a ``winder ctl`` command ("about half a
    second" was not what a command took) is a measurement, with its date."""
    text = " ".join(section(OPERATING, "From another shell").split())
    m = re.search(r"each command ends as soon as its answer is printed(.*?)Nothing waits", text)
    assert m, "OPERATING.md no longer says how long a winder ctl command takes"
    assert re.search(r"Measured on \d{4}-\d{2}-\d{2}", m.group(1)), m.group(1)


# -- the default job's numbers --------------------------------------------------------
#: README lines of `make demo`'s output that differ by machine, run or moment
MACHINE_LINES = ("recording into", "ROS domain", "run ", "real-time factor", "bag ", "part ")


@pytest.mark.ros
def test_the_default_jobs_numbers_are_what_a_run_prints_now(tmp_path: Path) -> None:
    """The default job wound and analysed: every line ANALYSIS.md shows of
    ``winder analyze`` on its bag (the first page's summary and "Default
    job"), and every line of the README's ``make demo`` output that does not
    name the machine, the run or the moment, is printed as shown."""
    domain = next_domain()
    env = {k: v for k, v in os.environ.items() if not k.startswith(("ROS_", "WINDER_", "FASTRTPS_"))}
    env.update(ROS_DOMAIN_ID=str(domain), ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST")
    try:
        run = subprocess.run(
            [str(BIN / "winder"), "run", "--bag-dir", str(tmp_path / "bags")],
            env=env,
            capture_output=True,
            text=True,
            timeout=300,
            stdin=subprocess.DEVNULL,
        )
    finally:
        release_domain(domain)
    assert run.returncode == 0, run.stdout + run.stderr
    [bag] = bags_in(tmp_path / "bags")
    analyze = subprocess.run(
        [str(BIN / "winder"), "analyze", str(bag), "--no-plots"],
        env=env,
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert analyze.returncode == 0, analyze.stdout + analyze.stderr
    bad = []
    printed = {line.rstrip() for line in analyze.stdout.splitlines()}
    for anchor in ("`winder analyze` on the default job's bag", "`winder run` with its defaults (RW400"):
        shown = [line.rstrip() for line in fenced_after(ANALYSIS, anchor) if line.strip()]
        assert len(shown) > 5, shown
        bad += [f"ANALYSIS.md ({anchor}): {line}" for line in shown if line not in printed]
    printed = {line.rstrip() for line in run.stdout.splitlines()}
    shown = [line.rstrip() for line in fenced_after(README, "`make demo` prints:")]
    kept = [line for line in shown if not line.strip().startswith(MACHINE_LINES)]
    assert len(kept) >= 6, kept
    bad += [f"README.md: {line}" for line in kept if line not in printed]
    # the machine's lines that name the part as the README shows them: the run's id, the index beside its bag
    index = (tmp_path / "bags" / "parts.sqlite").resolve()
    named = [f"  part               {bag.name}  (winder parts show)", f"  part index         {index}"]
    bad += [f"README.md (as: {line})" for line in named if line not in printed]
    assert not bad, (
        "lines the docs show that a run of the default job no longer prints:\n"
        + "\n".join(bad)
        + f"\n--- winder run:\n{run.stdout}\n--- winder analyze:\n{analyze.stdout}"
    )
