"""Who ran a part and with which wire (``operator``, ``wire_lot``): the run's
facts, not the recipe's (issue 56).

They are checked as a setting is, in one line naming the parameter, the
value and the rule, wherever they are typed (``winder run``, ``winder ctl
start``, a Wind goal, a job description); they travel in the job
description to the part; they never change the recipe's SHA-256, and a job
file cannot give them. Oracles: Python's own ``str.isprintable`` for the
rule, ``hashlib`` over the job file's bytes and over the job's canonical
text for the recipe, the index read with ``sqlite3`` for the part.
"""

from __future__ import annotations

import hashlib
import json
import sqlite3
import sys
import unicodedata
from pathlib import Path

import pytest
from support.cli import assert_one_line_error, run_cli

from winder.contract.jobfile import JobFileError, goal_sha256, load_job_file_hashed
from winder.contract.stream import (
    RUN_FACTS,
    RUN_TEXT_MAX,
    describe_job,
    parse_job_description,
)
from winder.errors import BadInputError
from winder.motion.job import Job
from winder.record.parts import PartEnd, PartIndex, part_start, recipe_sha256
from winder.spec import SpecError

RUN = "facts_20261130_101010123_1"
JOB = Job.from_dict({"job_id": "facts", "turns_per_layer": 3, "layers": 1, "poles": 2})
JOB_FILE = """\
interp_node:
  ros__parameters:
    job_id: facts
    turns_per_layer: 3
    layers: 1
    poles: 2
"""
#: what the rule must refuse, each for a reason of its own
BAD = {
    "a NUL (rcl cuts the string there)": "jane\x00doe",
    "a tab": "jane\tdoe",
    "a line feed": "jane\ndoe",
    "an escape sequence": "\x1b[2Jjane",
    "a C1 control": "jane\x85doe",
    "a right-to-left override": "jane\u202edoe",
    "a zero-width space": "jane\u200bdoe",
    "a lone surrogate (bytes of no UTF-8)": "jane\udcffdoe",
    "a leading space": " jane",
    "a trailing space": "jane ",
    "a double space": "jane  doe",
    "a no-break space": "jane\xa0doe",
    "too long": "x" * (RUN_TEXT_MAX + 1),
}
GOOD = ["", "jane", "Jane Doe", "Łukasz Müller-Ødegård", "山田 太郎", "LOT 2026/11-7#3", "x" * RUN_TEXT_MAX]


def test_the_rule_refuses_what_python_calls_unprintable() -> None:
    """Between two letters, a character is taken exactly when Python calls
    it printable (a space too), but for private-use and unassigned code
    points, which Python refuses and the rule may take (no C0/C1 control,
    no separator, no invisible format mark among them): every code point."""
    spec = RUN_FACTS["operator"]
    wrong = []
    for cp in range(sys.maxunicode + 1):
        c = chr(cp)
        text = f"a{c}b"
        try:
            spec.check(text)
            taken = True
        except SpecError:
            taken = False
        if unicodedata.category(c) in ("Co", "Cn") and not text.isprintable():
            continue
        if taken != text.isprintable():
            wrong.append(f"U+{cp:04X} ({unicodedata.category(c)}): taken {taken}")
    assert not wrong, wrong[:20]


@pytest.mark.parametrize("name", list(RUN_FACTS))
@pytest.mark.parametrize("why", list(BAD))
def test_a_bad_value_is_refused_in_one_line(name: str, why: str) -> None:
    value = BAD[why]
    with pytest.raises(SpecError) as caught:
        RUN_FACTS[name].check(value)
    text = str(caught.value)
    assert "\n" not in text, text
    # the parameter, the value as Python writes it (a NUL shows as \x00), the rule
    assert text.startswith(f"{name}={value!r} is invalid: must be printable text"), text
    assert f"printable text of at most {RUN_TEXT_MAX} characters" in text, text


@pytest.mark.parametrize("name", list(RUN_FACTS))
def test_good_values_are_taken_as_they_are(name: str) -> None:
    for value in GOOD:
        assert RUN_FACTS[name].check(value) == value


def test_the_command_lines_refuse_a_bad_value_in_one_line(tmp_path: Path) -> None:
    """``winder run`` and ``winder ctl start`` refuse before anything is
    started or sent: exit 2, one line naming the option's setting."""
    bags = tmp_path / "bags"
    r = run_cli("run", "--bag-dir", str(bags), "--operator=\x1b[2Jjane")
    assert_one_line_error(r, "winder run: error: operator='\\x1b[2Jjane' is invalid", "printable text")
    r = run_cli("run", "--bag-dir", str(bags), "--wire-lot=" + "x" * (RUN_TEXT_MAX + 1))
    assert_one_line_error(r, "winder run: error: wire_lot='xxx", f"at most {RUN_TEXT_MAX} characters")
    assert not bags.exists()
    r = run_cli("ctl", "start", "--timeout", "1", "--wire-lot", "lot\t7")
    assert_one_line_error(r, "winder ctl start: wire_lot='lot\\t7' is invalid")
    r = run_cli("ctl", "start", "--timeout", "1", "--operator", "jane", "--set", "operator=john")
    assert_one_line_error(r, "--operator and --set operator=... both given")


def test_ctl_start_sends_them_as_the_runs_settings() -> None:
    from winder.cli.commands import build_parser
    from winder.cli.ctl import run_values

    args = build_parser().parse_args(["ctl", "start", "--operator", "Jane Doe", "--set", "wire_lot=L-7"])
    assert run_values(args) == {"operator": "Jane Doe", "wire_lot": "L-7"}


def test_a_job_file_cannot_give_them(tmp_path: Path) -> None:
    """They are the run's: a job file naming them (in its interp_node section
    or in /**) is refused in one line saying where to give them instead."""
    for section in ("interp_node", "/**"):
        for name in RUN_FACTS:
            path = tmp_path / "f.yaml"
            path.write_text(f"{section}:\n  ros__parameters:\n    {name}: jane\n")
            with pytest.raises(JobFileError) as caught:
                load_job_file_hashed(path)
            text = str(caught.value)
            assert "\n" not in text and f"{name} is the run's, not the recipe's" in text, text
            assert f"--{name.replace('_', '-')}" in text, text


def test_the_recipes_hash_is_the_same_whoever_runs_it(tmp_path: Path) -> None:
    """Two runs of one recipe by two operators, with two wire lots, and one
    with neither: one recipe hash, the job's canonical text's (its fields as
    JSON, keys sorted, no spaces) without a job file, the file's bytes' with
    one."""
    plans = [
        parse_job_description(describe_job(JOB, RUN, operator="jane", wire_lot="L-1")),
        parse_job_description(describe_job(JOB, RUN, operator="john", wire_lot="L-2")),
        parse_job_description(describe_job(JOB, RUN)),
    ]
    assert [(p.operator, p.wire_lot) for p in plans] == [("jane", "L-1"), ("john", "L-2"), ("", "")]
    canonical = json.dumps(JOB.to_dict(), sort_keys=True, separators=(",", ":"))
    want = (hashlib.sha256(canonical.encode()).hexdigest(), "job_text")
    assert [recipe_sha256(p) for p in plans] == [want] * 3
    path = tmp_path / "facts.yaml"
    path.write_text(JOB_FILE)
    _, digest = load_job_file_hashed(path)
    assert digest == hashlib.sha256(path.read_bytes()).hexdigest()
    filed = [
        parse_job_description(describe_job(JOB, RUN, job_file_sha256=digest, operator=who))
        for who in ("jane", "john")
    ]
    assert [recipe_sha256(p) for p in filed] == [(digest, "job_file")] * 2


def test_a_description_with_a_bad_value_is_refused_in_one_line() -> None:
    doc = json.loads(describe_job(JOB, RUN, operator="jane"))
    for value, needle in (
        ("jane\x00doe", "job description: operator='jane\\x00doe' is invalid"),
        (42, "job description: operator 42 is not a text"),
    ):
        with pytest.raises(BadInputError) as caught:
            parse_job_description(json.dumps({**doc, "operator": value}))
        assert "\n" not in str(caught.value) and needle in str(caught.value), caught.value
    # a description of before them: neither
    old = {k: v for k, v in doc.items() if k not in RUN_FACTS}
    plan = parse_job_description(json.dumps(old))
    assert (plan.operator, plan.wire_lot) == ("", "")


def test_the_part_records_them_and_the_list_chooses_by_them(tmp_path: Path) -> None:
    """A part started from a description with them holds them (NULL without);
    ``winder parts list`` and ``export`` choose by them, exactly; a
    capability, which takes consecutive parts, refuses them in one line."""
    db = tmp_path / "parts.sqlite"
    index = PartIndex(db)
    given = [("jane", "L-1"), ("john", "L-1"), ("", "")]
    for n, (who, lot) in enumerate(given):
        plan = parse_job_description(
            describe_job(JOB, f"facts_20261130_10101012{n}_1", operator=who, wire_lot=lot)
        )
        start = part_start(
            plan, consumer="sim_node", simulated=True, software_version="0", started_ns=n, bag=""
        )
        part = index.begin(start)
        index.close(part, PartEnd(n + 10, {"state": "done", "steps_done": str(plan.total_steps)}))
    with sqlite3.connect(db) as con:
        rows = con.execute("SELECT operator, wire_lot FROM parts ORDER BY started_ns").fetchall()
    assert rows == [("jane", "L-1"), ("john", "L-1"), (None, None)]

    r = run_cli("parts", "list", "--db", str(db), "--operator", "john", "--json")
    assert r.returncode == 0, r.stderr
    assert [(p["operator"], p["wire_lot"]) for p in json.loads(r.stdout)] == [("john", "L-1")]
    r = run_cli("parts", "list", "--db", str(db), "--wire-lot", "L-1", "--json")
    assert [p["operator"] for p in json.loads(r.stdout)] == ["jane", "john"]
    r = run_cli("parts", "list", "--db", str(db), "--operator", "Jane", "--json")  # exactly: no part
    assert r.returncode == 0 and json.loads(r.stdout) == []
    out = tmp_path / "john.csv"
    r = run_cli("parts", "export", "--db", str(db), "--operator", "john", "--csv", str(out))
    assert r.returncode == 0, r.stderr
    assert len(out.read_text().splitlines()) == 2  # the header and john's part
    [part] = index.parts(operator="jane")
    r = run_cli("parts", "show", part["part_id"], "--db", str(db))
    shown = dict(line.split(None, 1) for line in r.stdout.splitlines() if line[:1].isalpha() and " " in line)
    assert (shown["operator"].strip(), shown["wire_lot"].strip()) == ("jane", "L-1"), r.stdout
    r = run_cli("parts", "capability", "--db", str(db), "--wire-lot", "L-1")
    assert_one_line_error(r, "--wire-lot L-1 cannot choose the parts of a capability")


def test_a_goals_operator_and_wire_lot_are_its_settings_and_hashed() -> None:
    """A Wind goal's ``operator_name`` and ``wire_lot`` set the interp node's
    ``operator`` and ``wire_lot`` for its run; they count in its hash as the
    overrides they stand for (a goal without them hashes as before they
    were fields); a value cut at a NUL on its way, a bad one, or one given
    twice is refused in one line."""
    from winder_interp.wind import goal_params

    params = goal_params("", ["layers=2"], operator="Jane Doe", wire_lot="L-7")
    assert {p.name: p.value for p in params} == {"layers": 2, "operator": "Jane Doe", "wire_lot": "L-7"}
    # the hash of a goal without them is the hash the Wind action had before them
    assert goal_sha256("job", ["layers=2"]) == hashlib.sha256(b"job\nlayers=2").hexdigest()
    sent = goal_sha256("", ["layers=2"], operator="Jane Doe", wire_lot="L-7")
    assert sent == hashlib.sha256(b"\nlayers=2\noperator=Jane Doe\nwire_lot=L-7").hexdigest()
    checked = goal_params("", ["layers=2"], sent, operator="Jane Doe", wire_lot="L-7")
    assert [(p.name, p.value) for p in checked] == [(p.name, p.value) for p in params]
    # what rcl makes of "Jane\x00Doe" on its way: "Jane", a valid name nobody asked for
    meant = goal_sha256("", [], operator="Jane\x00Doe")
    with pytest.raises(BadInputError, match=r"^goal_sha256: the goal came as .* overrides, operator hashing"):
        goal_params("", [], meant, operator="Jane")
    with pytest.raises(SpecError) as caught:
        goal_params("", [], operator="Jane\x1b[2J")
    assert str(caught.value).startswith("operator='Jane\\x1b[2J' is invalid: must be printable text")
    with pytest.raises(BadInputError, match="wire_lot given as a field and as an override"):
        goal_params("", ["wire_lot=L-1"], wire_lot="L-2")
