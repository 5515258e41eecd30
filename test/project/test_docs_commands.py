"""Every shell command the README and ``docs/*.md`` show in a ```sh block runs
on the pip install (this repository's .venv), as a reader would paste it: in
a fresh directory laid out like a checkout (``.venv``, ``jobs/``,
``layouts/``, the Makefile, a ``bags/`` directory holding one recording of
the default job), on a ROS domain of its own (conftest's domain lock), with
a timeout. So the docs cannot drift from the code again.

How a block is read:

* Lines starting with ``$ `` are commands and the lines after them their
  output; every other block is a script, one command a line (a trailing
  backslash continues it), run top to bottom with ``bash -e -o pipefail``
  so that a block's variables (``BAG=$(ls -td bags/*/ | head -1)``) carry;
  a ``$`` line runs on its own (``-o pipefail``), as typed.
* A ``$`` command whose output shows ``: error:`` must fail (exit status not
  0), every other command must succeed; no command may print a traceback.
* An HTML comment on the line before the block says more:
  ``<!-- doc-test: same output -->`` every line of the shown output must be
  in the command's output; ``<!-- doc-test: serve (why) -->`` the commands
  start something that runs until stopped (a real-time run, a paused
  player): up after a few seconds counts; ``<!-- doc-test: skip (why) -->``
  the block is not run here (a second host, minutes of tests): the reason
  says why.
* Lines for a ROS install (``ros2 ...``, ``colcon ...``, ``source ...``) are
  not run: ros2cli, launch and colcon's workspaces are not part of the pip
  install (the node executables they start are run by ``test_node_processes.py``,
  the colcon build too).
* What is not run is checked without running it: every part of it that is
  winder's (subcommands and options, node parameters and their ranges,
  launch arguments, services and their types, make targets, test paths)
  must exist (``support/doc_commands.py``).
"""

from __future__ import annotations

import contextlib
import os
import re
import shlex
import shutil
import signal
import subprocess
import tempfile
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path

import pytest
from conftest import BIN, next_domain, release_domain
from support import wait
from support.doc_commands import problems
from support.paths import ROOT

from winder.procs import popen

DOCS = [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]

#: commands of a ROS install, not of the pip install
ROS_INSTALL = {
    "ros2": "ros2cli is not installable as wheels: for a ROS 2 install",
    "colcon": "a colcon workspace (test_node_processes.py builds one)",
    "source": "sourcing a ROS install's setup script",
}
MARKER = re.compile(r"^\s*<!--\s*doc-test:\s*(skip|serve|same output)\s*(?:\((.*)\))?\s*-->")
#: a block's commands end within this (the slowest, a 4.4 M-step job, takes ~10 s here)
TIMEOUT_S = 300.0
#: a served command counts as up when it still runs after this
SERVE_S = 8.0


@dataclass
class Command:
    text: str
    line: int
    output: list[str] = field(default_factory=list)


@dataclass
class Block:
    path: Path
    line: int
    kind: str  # "script" or "dollar"
    marker: str  # "", "skip", "serve", "same output"
    reason: str
    commands: list[Command]
    not_run: list[tuple[Command, str]]

    @property
    def name(self) -> str:
        return f"{self.path.relative_to(ROOT)}:{self.line}"


def _open_quote(text: str) -> bool:
    """Whether a quotation runs on into the next line (shell syntax)."""
    try:
        shlex.split(text, comments=True)
    except ValueError:
        return True
    return False


def _logical(lines: list[tuple[int, str]]) -> list[tuple[int, str]]:
    """Lines joined where a trailing backslash or an open quotation continues them."""
    out: list[tuple[int, str]] = []
    pending: tuple[int, str] | None = None
    for n, text in lines:
        if pending is not None:
            n, text = pending[0], pending[1] + "\n" + text
            pending = None
        if text.rstrip().endswith("\\") or _open_quote(text):
            pending = (n, text)
        else:
            out.append((n, text))
    if pending is not None:
        out.append(pending)
    return out


def _ros_install(text: str) -> str:
    word = text.split(maxsplit=1)[0] if text.split() else ""
    return ROS_INSTALL.get(word, "")


def parse(path: Path) -> list[Block]:
    """The ```sh blocks of one Markdown file."""
    lines = path.read_text().splitlines()
    blocks: list[Block] = []
    i = 0
    while i < len(lines):
        if lines[i].strip() != "```sh":
            i += 1
            continue
        start = i + 1
        prev = next((lines[j] for j in range(i - 1, -1, -1) if lines[j].strip()), "")
        m = MARKER.match(prev)
        marker, reason = (m.group(1), (m.group(2) or "").strip()) if m else ("", "")
        body: list[tuple[int, str]] = []
        i += 1
        while i < len(lines) and lines[i].strip() != "```":
            body.append((i + 1, lines[i]))
            i += 1
        i += 1
        dollar = any(text.startswith("$ ") for _, text in body)
        commands: list[Command] = []
        not_run: list[tuple[Command, str]] = []
        if dollar:
            for n, text in _logical(body):
                if text.startswith("$ "):
                    commands.append(Command(text[2:], n))
                elif commands and text.strip() and text.strip() != "...":
                    commands[-1].output.append(text.rstrip())
        else:
            for n, text in _logical(body):
                stripped = text.strip()
                if stripped and not stripped.startswith("#"):
                    commands.append(Command(stripped, n))
        for c in list(commands):
            why = _ros_install(c.text)
            if why:
                commands.remove(c)
                not_run.append((c, why))
        blocks.append(Block(path, start, "dollar" if dollar else "script", marker, reason, commands, not_run))
    return blocks


BLOCKS = [b for path in DOCS for b in parse(path)]


def _params() -> list[object]:
    """The blocks that run here (the others: :func:`_not_run`)."""
    return [pytest.param(b, id=b.name) for b in BLOCKS if b.marker != "skip" and b.commands]


def _not_run() -> list[object]:
    """Each block with commands that are not run here (a skip marker, a ROS
    install's lines), with those commands: checked without running them."""
    params: list[object] = []
    for b in BLOCKS:
        lines = [c for c, _ in b.not_run]
        if b.marker == "skip" or not b.commands:
            lines = [*b.commands, *lines]
        if lines:
            params.append(pytest.param(b, lines, id=b.name))
    return params


@pytest.fixture(scope="module")
def checkout(tmp_path_factory: pytest.TempPathFactory) -> Iterator[tuple[Path, dict[str, str]]]:
    """A directory laid out like a checkout, an environment on a domain of its
    own, and one recording of the default job in ``bags/``."""
    venv = BIN.parent
    assert (venv / ".winder-installed").exists(), f"{venv} was not made by `make venv`"
    work = tmp_path_factory.mktemp("docs_commands")
    (work / ".venv").symlink_to(venv)
    # winder_interfaces: the definitions make builds (up to date in the venv: nothing to build)
    for d in ("jobs", "layouts", "winder_interfaces"):
        shutil.copytree(ROOT / d, work / d)
    shutil.copy(ROOT / "Makefile", work / "Makefile")
    # the Makefile's venv stamp depends on the setup files: stand-ins older than
    # the stamp, so that `make demo` runs the demo and never reinstalls the venv
    setups = re.search(r"^SETUPS\s*:=\s*(.*?)(?<!\\)\n", (ROOT / "Makefile").read_text(), re.M | re.S)
    assert setups is not None
    for name in setups.group(1).replace("\\\n", " ").split():
        stub = work / name
        stub.parent.mkdir(parents=True, exist_ok=True)
        stub.write_text("")
        os.utime(stub, (0, 0))
    domain = next_domain()
    env = {k: v for k, v in os.environ.items() if not k.startswith(("ROS_", "WINDER_", "FASTRTPS_"))}
    env.update(
        ROS_DOMAIN_ID=str(domain),
        ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST",
        PWD=str(work),
    )
    r = subprocess.run(
        [".venv/bin/winder", "run", "--bag-dir", "bags"],
        cwd=work,
        env=env,
        capture_output=True,
        text=True,
        timeout=TIMEOUT_S,
        stdin=subprocess.DEVNULL,
    )
    assert r.returncode == 0, r.stdout + r.stderr
    try:
        yield work, env
    finally:
        release_domain(domain)


def _run(
    script: str, work: Path, env: dict[str, str], errexit: bool = True
) -> subprocess.CompletedProcess[str]:
    """``script`` in bash, as pasted: a script block stops at its first
    failing command (-e); a ``$`` line is one command line, as typed. What
    the script left running (a block that starts nodes in the background and
    failed before it stopped them) is stopped after it, so that it cannot
    hold the output pipes open or join the next block's graph."""
    with tempfile.TemporaryFile("w+") as out, tempfile.TemporaryFile("w+") as err:
        p = popen(
            ["bash", *(["-e"] if errexit else []), "-o", "pipefail", "-c", script],
            cwd=work,
            env=env,
            stdout=out,
            stderr=err,
            text=True,
            stdin=subprocess.DEVNULL,
            start_new_session=True,
        )
        try:
            code = p.wait(timeout=TIMEOUT_S)
        finally:
            _stop_group(p.pid)
            p.wait()
        out.seek(0)
        err.seek(0)
        return subprocess.CompletedProcess(p.args, code, out.read(), err.read())


def _stop_group(pgid: int) -> None:
    """SIGINT to what is left of a block's process group (as Ctrl-C), SIGKILL after 10 s."""

    def gone() -> bool:
        try:
            os.killpg(pgid, 0)
        except ProcessLookupError:
            return True
        return False

    for sig, grace in ((signal.SIGINT, 10.0), (signal.SIGKILL, 0.0)):
        try:
            os.killpg(pgid, sig)
        except ProcessLookupError:
            return
        try:
            wait.until(gone, grace, f"end of process group {pgid} after {sig.name}", poll=0.1)
            return
        except wait.WaitTimeoutError:
            continue  # its grace is over: the next signal (nothing fails here: a stop)


def _serve(script: str, work: Path, env: dict[str, str]) -> tuple[int | None, str]:
    """Start ``script``; None and its output so far if it still runs after
    SERVE_S (then it is stopped with SIGINT, as Ctrl-C would), else its status."""
    p = popen(
        ["bash", "-e", "-o", "pipefail", "-c", script],
        cwd=work,
        env=env,
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
        stdin=subprocess.DEVNULL,
        start_new_session=True,
    )
    # the subject is what does not happen: a served command does not end within SERVE_S
    with contextlib.suppress(subprocess.TimeoutExpired):
        p.wait(timeout=SERVE_S)
    if p.poll() is not None:
        out, _ = p.communicate()
        return p.returncode, out
    os.killpg(p.pid, signal.SIGINT)
    try:
        out, _ = p.communicate(timeout=30)
    except subprocess.TimeoutExpired:
        os.killpg(p.pid, signal.SIGKILL)
        out, _ = p.communicate()
    return None, out


@pytest.mark.ros
@pytest.mark.parametrize("block", _params())
def test_the_docs_commands_run(block: Block, checkout: tuple[Path, dict[str, str]]) -> None:
    work, env = checkout
    if block.kind == "script":
        script = "\n".join(c.text for c in block.commands)
        if block.marker == "serve":
            code, out = _serve(script, work, env)
            assert code in (None, 0), f"{block.name}: exit {code}\n{out}"
        else:
            r = _run(script, work, env)
            out = r.stdout + r.stderr
            assert r.returncode == 0, f"{block.name}: exit {r.returncode}\n{out}"
        assert "Traceback" not in out, f"{block.name}\n{out}"
        return
    for c in block.commands:
        r = _run(c.text, work, env, errexit=False)
        out = r.stdout + r.stderr
        where = f"{block.path.relative_to(ROOT)}:{c.line}: $ {c.text}"
        assert "Traceback" not in out, f"{where}\n{out}"
        if any(": error:" in line for line in c.output):
            assert r.returncode != 0, f"{where}: shown failing, exit 0\n{out}"
        else:
            assert r.returncode == 0, f"{where}: exit {r.returncode}\n{out}"
        if block.marker == "same output":
            got = {line.rstrip() for line in out.splitlines()}
            missing = [line for line in c.output if line not in got]
            assert not missing, (
                f"{where}: the doc shows lines the command no longer prints:\n"
                + "\n".join(missing)
                + f"\n--- it printed:\n{out}"
            )


@pytest.mark.parametrize(("block", "lines"), _not_run())
def test_the_docs_commands_not_run_name_only_what_winder_has(block: Block, lines: list[Command]) -> None:
    """A command the docs show that cannot run here (a ROS install's ``ros2
    run``/``launch``/``service call``, a second host, minutes of tests) names
    only what winder has: its subcommands and options parse, its nodes'
    parameters exist and are in range, the launch arguments, services and
    service types, make targets and test paths exist
    (``support/doc_commands.py``). Another project's commands are not
    checked, but every such block holds at least one of winder's."""
    checked, bad = 0, []
    for c in lines:
        found = problems(c.text)
        if found is None:
            continue
        checked += 1
        bad += [f"{block.path.relative_to(ROOT)}:{c.line}: {p}" for p in found]
    assert not bad, "\n".join(bad)
    assert checked, f"{block.name}: none of its commands is winder's: {[c.text for c in lines]}"


@pytest.mark.parametrize(
    "text",
    [
        ".venv/bin/winder run --no-such-option 3",
        ".venv/bin/winder analyse bags/x",
        ".venv/bin/sim_node --ros-args -p fork.Q:=1",
        ".venv/bin/sim_node --ros-args -p fork.J:=-1",
        "ros2 run winder_sim sim_nodes --ros-args -p model:=nonlinear",
        "ros2 run winder_profile profile_node --ros-args -p tau:=fast",
        "ros2 launch winder_sim winder.launch.py turns:=40",
        "ros2 launch winder_sim winder_cell.launch.py",
        "ros2 service call /cell1/interp_node/begin std_srvs/srv/Trigger",
        "ros2 service call /interp_node/start_run std_srvs/srv/Trigger",
        "make tests",
        ".venv/bin/python -m pytest test/contract/test_conformances.py",
        'WINDER_CONSUMER="bridge_node --ros-args -p max_following_error.hand:=1" make test',
        "ros2 run winder_sim sim_node --ros-args -p model:=quadratic",
        "ros2 param set /cell1/interp_node turns_per_layer 0",
        "ros2 param get /interp_node job",
    ],
)
def test_a_command_not_run_that_names_what_winder_lacks_is_found(text: str) -> None:
    """The check above can fail: each of these names something winder does
    not have (a misspelt option, parameter, executable, launch file or
    argument, service or its type, target or path, an out-of-range value)."""
    found = problems(text)
    assert found, text
    assert all("\n" not in line for line in found), found


@pytest.mark.parametrize(
    "text",
    [
        ".venv/bin/winder run --turns-per-layer 10 --one-process",
        "ros2 run winder_sim sim_node --ros-args -r __ns:=/cell1 -p model:=nonlinear -p fork.D:=0.003",
        "ros2 launch winder_sim winder.launch.py turns_per_layer:=40 profile:=trapezoid fork.J:=2e-4",
        "ros2 service call /cell1/interp_node/start std_srvs/srv/Trigger",
        "ros2 service call /sim_node/change_state lifecycle_msgs/srv/ChangeState",
        "ros2 param set /interp_node job_file jobs/rw400.yaml",
        "WINDER_TEST_DOMAINS=20-59 nice -n 5 .venv/bin/python -m pytest test/analysis/test_metrics.py",
    ],
)
def test_a_command_not_run_that_names_what_winder_has_passes(text: str) -> None:
    assert problems(text) == [], text
    assert problems("xacro winder.urdf.xacro") is None  # another project's: not checked


def test_every_block_is_read_and_every_skip_says_why() -> None:
    """The parser finds the blocks (a README without commands would pass
    the test above vacuously), every skip marker gives its reason, and only
    the lines of a ROS install are left out of a block that runs."""
    assert len(BLOCKS) >= 20, [b.name for b in BLOCKS]
    runnable = [b for b in BLOCKS if b.marker != "skip" and b.commands]
    assert len(runnable) >= 15, [b.name for b in runnable]
    for b in BLOCKS:
        assert b.marker != "skip" or len(b.reason) > 10, f"{b.name}: a skip marker must say why"
        assert b.commands or b.not_run or b.marker == "skip", f"{b.name}: an empty ```sh block"
        for c, why in b.not_run:
            assert c.text.split()[0] in ROS_INSTALL and why, (b.name, c.text)
    readme = [b for b in BLOCKS if b.path.name == "README.md"]
    assert any("make demo" in c.text for b in readme for c in b.commands), "the README's front door"


def test_markers_sit_on_a_block() -> None:
    """A doc-test marker that is not right before a ```sh block is a typo
    that would silently run (or not skip) something."""
    for path in DOCS:
        lines = path.read_text().splitlines()
        for n, text in enumerate(lines):
            if MARKER.match(text):
                after = next((t for t in lines[n + 1 :] if t.strip()), "")
                assert after.strip() == "```sh", f"{path.name}:{n + 1}: marker not followed by a ```sh block"


def _cells(row: str) -> int:
    """Cells of a Markdown table row: ``|`` outside code spans, unescaped."""
    count, code, prev = 0, False, ""
    for ch in row.strip().strip("|"):
        if ch == "`":
            code = not code
        elif ch == "|" and not code and prev != "\\":
            count += 1
        prev = ch
    return count + 1


def test_every_table_row_has_its_headers_cells() -> None:
    """A table whose rows have more or fewer cells than its header renders
    shifted (the resonance table once had 18 header cells and 13 per row)."""
    bad = []
    for path in DOCS:
        fenced = False
        header = 0
        for n, text in enumerate(path.read_text().splitlines(), 1):
            if text.lstrip().startswith("```"):
                fenced = not fenced
            if fenced or not text.startswith("|"):
                header = 0
                continue
            if not header:
                header = _cells(text)
            elif _cells(text) != header:
                bad.append(f"{path.name}:{n}: {_cells(text)} cells, the header has {header}")
    assert not bad, "\n".join(bad)


def _anchors(path: Path) -> set[str]:
    """The heading anchors of a Markdown file, as GitHub makes them."""
    out, fenced = set(), False
    for line in path.read_text().splitlines():
        if line.lstrip().startswith("```"):
            fenced = not fenced
        m = None if fenced else re.match(r"^#+\s+(.*)", line)
        if m:
            out.add(re.sub(r"[^\w\- ]", "", m.group(1).strip().lower()).replace(" ", "-"))
    return out


def test_every_relative_link_resolves() -> None:
    """Links between the README and the docs point at files and headings
    that exist (the docs were moved around once; a link left behind is
    found here, not by a reader)."""
    bad = []
    for path in [*DOCS, ROOT / "CHANGELOG.md"]:
        text = re.sub(r"```.*?```", "", path.read_text(), flags=re.S)
        for m in re.finditer(r"\]\(([^)\s]+)\)", text):
            target = m.group(1)
            if re.match(r"[a-z]+:", target):
                continue
            file, _, anchor = target.partition("#")
            dest = path.parent / file if file else path
            if not dest.exists():
                bad.append(f"{path.name}: {target}: no such file")
            elif anchor and dest.suffix == ".md" and anchor not in _anchors(dest):
                bad.append(f"{path.name}: {target}: no such heading")
    assert not bad, "\n".join(bad)
