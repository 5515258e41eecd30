"""What `winder run`, `winder analyze` and their figures say about a run is
true: the commanded jerk of a
run with a pause and a programmed stop, the figures of an aborted run and of a
one-pole job, the summary of a shaped run with commands, the name of a
re-simulation, the time `winder bag recover` names.

Every run is a real cell (`winder run`, the three nodes over DDS), read back
from its bag. The oracles are written here: a cubic fitted to the step times
of each stretch of steady motion (numpy's least squares), the recorded
events, the artists of the figures (title, legend texts, lines).
"""

from __future__ import annotations

import os
import re
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from conftest import next_domain, release_domain

from winder.analysis.metrics import analyze
from winder.record.bag import bags_in
from winder.record.reader import read_run

pytestmark = pytest.mark.ros

WINDER = Path(sys.executable).with_name("winder")
JOB = ["--turns-per-layer", "8", "--layers", "1", "--poles", "2", "--fork-steps-per-rev", "512"]
J_MAX = 65536.0  # steps/s^3, the profile's default jerk limit
FORK_STEP = 2 * np.pi / 512  # rad per fork step


class Cell:
    """`winder run` in a domain of its own; each run's bag and output kept."""

    def __init__(self, root: Path, domain: int) -> None:
        self.root = root
        self.env = {
            **os.environ,
            "ROS_DOMAIN_ID": str(domain),
            "ROS_AUTOMATIC_DISCOVERY_RANGE": "LOCALHOST",
        }
        self.runs: dict[str, tuple[Path, str]] = {}

    def winder(self, *args: str, code: int = 0) -> str:
        out = subprocess.run([str(WINDER), *args], env=self.env, capture_output=True, text=True, timeout=240)
        assert out.returncode == code, out.stdout + out.stderr
        return out.stdout

    def run(self, tag: str, *args: str, code: int = 0) -> tuple[Path, str]:
        if tag not in self.runs:
            out = self.winder("run", *JOB, "--bag-dir", str(self.root / tag), *args, code=code)
            [bag] = bags_in(self.root / tag)
            self.runs[tag] = bag, out
        return self.runs[tag]


@pytest.fixture(scope="module")
def cell(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Cell]:
    domain = next_domain()
    try:
        yield Cell(tmp_path_factory.mktemp("honest"), domain)
    finally:
        release_domain(domain)


PAUSED = ("--stops", "1:4", "--stop-pause", "0.3", "--schedule", "pause@0.8,resume@1.2")


# -- 1. the commanded jerk of a run with a pause and a programmed stop -----------------------------


def fitted_peak_jerk(t_ns: np.ndarray, window: int = 64, max_gap: float = 0.01) -> float:
    """The largest |jerk| (steps/s^3) of cubics k(t) fitted by least squares to
    windows of ``window`` consecutive steps, only where no two steps of the
    window are more than ``max_gap`` s apart (the axis in motion, not at or
    near a rest)."""
    t = np.asarray(t_ns, dtype=np.float64) * 1e-9
    gap = np.diff(t)
    ok = np.concatenate([[False], gap < max_gap])  # step i follows step i - 1 closely
    peak = 0.0
    for i in range(0, t.size - window, window // 4):
        if not np.all(ok[i + 1 : i + window]):
            continue
        tw = t[i : i + window] - t[i]
        c = np.polyfit(tw, np.arange(window, dtype=np.float64), 3)
        peak = max(peak, abs(6 * c[0]))
    return peak


def test_a_pause_and_a_programmed_stop_leave_the_commanded_jerk_at_its_limit(cell: Cell) -> None:
    """pause@0.8 / resume@1.2 and a programmed stop in the first layer: the
    fork's commanded peak jerk is the ramp's limit (65536 steps/s^3 = 804
    rad/s^3 with 512 steps a turn), as a cubic fitted to the step times of
    each stretch of motion says; it was 2e5 rad/s^3 (the kinematics
    differentiated across the rests)."""
    bag, _ = cell.run("paused", *PAUSED)
    run = read_run(bag)
    assert run.complete and [e["event"] for e in run.events] == ["pause", "resume"]
    rows = run.steps
    fork = rows[rows[:, 1] == 0]  # the first layer: the fork is its major axis
    fitted = fitted_peak_jerk(fork[:, 0])
    assert 0.9 * J_MAX < fitted < 1.1 * J_MAX  # the oracle sees the limit reached, and no more
    result = analyze(run)
    limit = J_MAX * FORK_STEP
    got = result.axes["fork"].cmd_j
    assert 0.95 * limit <= got <= 1.02 * limit, (got, limit)
    # the feed moves with the fork along the layer: its jerk scales with its share of the steps
    feed = result.axes["feed"].cmd_j
    assert feed <= 1.02 * J_MAX * (2000 / 4096) * 1e-5, feed  # 2000 feed steps of 10 um a layer


def test_the_commanded_jerk_stays_at_its_limit_where_the_jerk_jumps_by_twice_it(cell: Cell) -> None:
    """Feed override 0.5 with a pause: the moves at half speed never reach
    a_max, their acceleration is a triangle and the jerk jumps from +J to -J
    at its peak. The fork's commanded peak jerk is the limit, as the fitted
    cubics say; the stencil's 3 a^2 / v - t3 v^4 gave 907.5 rad/s^3 (+13 %)
    there (and 453.7 against 402 for the pole's index moves of the default job)."""
    bag, _ = cell.run("override", *PAUSED, "--feed-override", "0.5")
    run = read_run(bag)
    assert run.complete
    rows = run.steps
    assert 0.9 * J_MAX < fitted_peak_jerk(rows[rows[:, 1] == 0][:, 0]) < 1.1 * J_MAX
    got = analyze(run).axes["fork"].cmd_j
    limit = J_MAX * FORK_STEP
    assert 0.95 * limit <= got <= 1.02 * limit, (got, limit)


# -- 6. `winder bag recover` names the time it recovered up to truly ---------------------------------


def test_bag_recover_names_simulated_time_since_the_start_not_an_epoch(cell: Cell, tmp_path: Path) -> None:
    """A cut copy of a recording: `winder bag recover` says up to which
    simulated time since the job's start it recovered (within the run's 6.5
    s), and calls the log time what it is; it said "t = 1795655718.089 s of
    simulated time" (the wall-clock start plus simulated time)."""
    bag, _ = cell.run("paused", *PAUSED)
    run = read_run(bag)
    sim_end = float(run.report["sim_time_s"])
    cut = tmp_path / "cut"
    cut.mkdir()
    [mcap] = list(bag.glob("*.mcap"))
    data = mcap.read_bytes()
    (cut / mcap.name).write_bytes(data[: len(data) * 2 // 3])
    said = cell.winder("bag", "recover", str(cut))
    [line] = [s for s in said.splitlines() if s.startswith("recovered ")]
    m = re.search(r"up to t = ([0-9.]+) s of simulated time since the job's start", line)
    assert m is not None, line
    assert 0.0 <= float(m.group(1)) <= sim_end, line
    wall = run.sim_config.wall_start_ns if run.sim_config else 0
    assert wall > 0
    assert "log time 20" in line and "UTC" in line, line  # the date the log times stand for


# -- 5. a re-simulation is named and labelled as one ----------------------------------------------


def test_a_resimulated_bag_reads_as_a_resimulation(cell: Cell, tmp_path: Path) -> None:
    """`winder resim` of a run: the new bag's name (its run id) says
    ``resim`` and metadata.yaml's custom_data names the run and the bag it
    re-simulates; it was named like a live run (rw400_<date>_<time>_1)."""
    import yaml

    bag, _ = cell.run("paused", *PAUSED)
    source = read_run(bag)
    said = cell.winder("resim", str(bag), "--fork.J", "2e-4", "--bag-dir", str(tmp_path / "out"))
    [new] = bags_in(tmp_path / "out")
    assert new.name.startswith(f"{source.job_id}_resim_"), new.name
    assert f"bag                {new}" in said, said
    run = read_run(new)
    assert run.run_id == new.name and run.plan.source_run_id == source.run_id
    meta = yaml.safe_load((new / "metadata.yaml").read_text())["rosbag2_bagfile_information"]
    custom = meta["custom_data"]
    assert custom["winder_run"] == "re-simulation", custom
    assert custom["winder_source_run_id"] == source.run_id, custom
    assert custom["winder_source_bag"] == str(bag.resolve()), custom
    assert analyze(run).source  # the analysis names the source as before


# -- 4. the summaries name the shaper, the programmed stops and the operator's commands ---------------

SHAPED = (
    *("--shaper", "zvd", "--shaper-freq", "12.5", "--stops", "1:4", "--stop-pause", "0.3"),
    *("--schedule", "pause@0.8,resume@1.2,override@2.0=0.5"),
)


def lines_with(text: str, head: str) -> list[str]:
    return [s.strip() for s in text.splitlines() if s.strip().startswith(head)]


def test_the_summaries_name_the_shaper_the_stops_and_the_commands(cell: Cell) -> None:
    """A ZVD-shaped run with a programmed stop, a pause, a resume and an
    override: `winder run`'s header and `winder analyze`'s profile row name
    the shaper and its frequency, both summaries have a line for the stop
    (coil:turn, rest) and one for the commands (each with its time and
    where the axes came to rest); they said "scurve profile" and nothing of
    either. A run without any has neither line."""
    bag, said = cell.run("shaped", *SHAPED)
    assert said.splitlines()[0].endswith("scurve profile, ZVD shaper at 12.5 Hz, linear motor model"), said
    for text in (said, cell.winder("analyze", str(bag), "--no-plots")):
        [stops] = lines_with(text, "programmed stops")
        assert "1 (1:4, rest 0.3 s, auto)" in stops, stops
        [commands] = lines_with(text, "operator commands")
        run = read_run(bag)
        pause = run.events[0]
        assert [e["event"] for e in run.events] == ["pause", "resume", "override"]
        rest = pause["t_rest_ns"] / 1e9
        assert f"pause at 0.800 s (at rest {rest:.3f} s, coil 1 turn " in commands, commands
        assert "resume at 1.200 s" in commands and "override x0.5 at 2.000 s" in commands, commands
    [profile] = lines_with(cell.winder("analyze", str(bag), "--no-plots"), "profile / motor model")
    assert profile.endswith("scurve, ZVD shaper at 12.5 Hz / linear"), profile
    plain, said = cell.run("plain")
    assert said.splitlines()[0].endswith("scurve profile, linear motor model"), said
    for text in (said, cell.winder("analyze", str(plain), "--no-plots")):
        assert not lines_with(text, "programmed stops") and not lines_with(text, "operator commands"), text


# -- 2. operations.png of an aborted run -------------------------------------------------------------

ABORTED = ("--schedule", "pause@0.5,resume@0.8,pause@1.2,resume@1.5,abort@2.2")


def figure_of(name: str, bag: Path) -> Any:
    """The matplotlib figure ``name`` as winder analyze draws it, before it is saved."""
    from winder.analysis.figures import analysis as fa
    from winder.analysis.metrics import digest_run

    run = read_run(bag)
    return getattr(fa, f"{name}_figure")(run, digest_run(run))


def test_operations_png_of_an_aborted_run_says_so_once_and_shows_the_abort(
    cell: Cell, tmp_path: Path
) -> None:
    """Two pauses and an abort: the title says the run was aborted, when and
    where (not "incomplete"); every legend entry is there once; the line where
    the axes came to rest after the abort is inside the axes, clear of the
    frame. The title said "(incomplete)", the two pauses gave the legend each
    of their entries twice, and the plot ended at the last sample, 0.05 s after
    that rest."""
    bag, _ = cell.run("aborted", *ABORTED, code=3)
    run = read_run(bag)
    abort = run.events[-1]
    assert abort["event"] == "abort" and run.report["state"] == "aborted"
    fig = figure_of("operations", bag)
    title = fig._suptitle.get_text()
    assert "incomplete" not in title, title
    assert f"aborted at {abort['t_ns'] / 1e9:.3f} s" in title and "coil 1 turn " in title, title
    labels = [t.get_text() for ax in fig.axes if ax.get_legend() for t in ax.get_legend().get_texts()]
    labels += [t.get_text() for leg in fig.legends for t in leg.get_texts()]
    assert labels and len(labels) == len(set(labels)), labels
    assert any("abort" in s and "rest" in s for s in labels), labels
    rest = abort["t_rest_ns"] / 1e9
    for ax in fig.axes:
        lo, hi = ax.get_xlim()
        xs = [line.get_xdata()[0] for line in ax.get_lines() if len(line.get_xdata()) == 2]
        assert any(abs(x - rest) < 1e-9 for x in xs)  # the abort's rest is marked
        assert lo < rest and hi - rest >= 0.05 * (hi - lo), (lo, rest, hi)


# -- 3. motion.png: a short title, jerk that reads as a curve, no panel for an axis that never moves ---


def stripes(ax: Any) -> int:
    """Segments of the axes' drawn lines that cross its whole height (a line
    between two samples beyond the opposite edges: a vertical stripe)."""
    lo, hi = ax.get_ylim()
    n = 0
    for line in ax.get_lines():
        if line.get_linestyle() in ("None", "", " ", "none"):
            continue
        y = np.asarray(line.get_ydata(), dtype=float)
        if y.size < 2:
            continue
        a, b = y[:-1], y[1:]
        n += int(np.count_nonzero(((a < lo) & (b > hi)) | ((a > hi) & (b < lo))))
    return n


def test_motion_png_has_a_short_title_jerk_curves_and_no_empty_pole_panels(cell: Cell) -> None:
    """A one-pole job (the pole axis never moves): motion.png has no panel for
    the pole, a title of one line and a short subtitle, and no jerk panel
    drawn as vertical stripes. It had a three-line title, three pole panels
    saying "does not move" and a sampled axis jerk of +-2e4 drawn as lines
    through a panel clipped at +-2000."""
    bag, _ = cell.run("onepole", "--poles", "1")
    fig = figure_of("motion", bag)
    lines = fig._suptitle.get_text().splitlines()
    assert 1 <= len(lines) <= 2 and all(len(s) <= 130 for s in lines), lines
    texts = [t.get_text() for ax in fig.axes for t in ax.texts]
    assert not any("does not move" in t for t in texts), texts
    assert not any(ax.get_title().startswith("pole") for ax in fig.axes)
    assert not any("pole" in ax.get_ylabel() for ax in fig.axes)
    jerk = [ax for ax in fig.axes if "jerk" in ax.get_ylabel()]
    assert len(jerk) == 2  # feed and fork
    for ax in jerk:
        assert stripes(ax) == 0, ax.get_ylabel()
        assert any(len(line.get_xdata()) > 10 for line in ax.get_lines())  # the command is drawn
