"""The figures and the analysis say what the run was (issue 54, item 5):
a coil's turns as laid (never a product that rounds them), the flyer's speed
in wire.png's peak panel as recorded there, an x label on every panel of
winding.png, and a driver's read-back not differentiated as motion.

Oracles: the turns a window holds counted here from its width and the wire
(odd layers W/d, the shifted even ones one less), the joint samples of the
bag (read with the reader), the bag a real mock driver recorded.
"""

from __future__ import annotations

import math
import os
import re
import subprocess
import sys
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from support.paths import ROOT

from winder.motion.axes import AXES
from winder.record.bag import bags_in
from winder.record.reader import read_run

pytestmark = pytest.mark.ros  # each test winds a coil: real nodes over DDS

WINDER = Path(sys.executable).with_name("winder")
WIDTH, WIRE, LAYERS = 0.005, 0.0005, 3  # jobs/ortho_round.yaml in a 5 mm window, 3 layers


@pytest.fixture(scope="module")
def ortho(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """An orthocyclic coil of 3 layers wound by `winder run` (its own domain)."""
    from support.domains import next_domain, release_domain

    out = tmp_path_factory.mktemp("ortho")
    domain = next_domain()
    try:
        r = subprocess.run(
            [str(WINDER), "run", str(ROOT / "jobs" / "ortho_round.yaml"), "--layers", str(LAYERS),
             "--bobbin.window-width", str(WIDTH), "--bag-dir", str(out)],
            env={**os.environ, "ROS_DOMAIN_ID": str(domain), "ROS_AUTOMATIC_DISCOVERY_RANGE": "LOCALHOST"},
            capture_output=True, text=True, timeout=300, stdin=subprocess.DEVNULL,
        )  # fmt: skip
    finally:
        release_domain(domain)
    assert r.returncode == 0, r.stdout + r.stderr
    [bag] = bags_in(out)
    return bag


def test_the_turns_are_named_as_laid(ortho: Path) -> None:
    """179 turns were "3 layers x 60 turns": the title and the table say each layer's count."""
    from winder.analysis.figures.analysis import _title

    full = math.floor(WIDTH / WIRE + 1e-9)  # layer 1 lies against the flange: W/d turns
    shifted = math.floor((WIDTH - WIRE / 2) / WIRE + 1e-9)  # shifted by d/2: one fewer fits
    per_layer = [full if k % 2 == 0 else shifted for k in range(LAYERS)]
    said = f"1 pole x {sum(per_layer)} turns in {LAYERS} layers ({', '.join(map(str, per_layer))})"
    run = read_run(ortho)
    assert said in _title(run)  # every figure's title, wound.png's included
    r = subprocess.run([str(WINDER), "analyze", str(ortho)], capture_output=True, text=True, timeout=180)
    assert r.returncode == 0, r.stderr
    assert re.search(rf"^job\s+{re.escape(said)}, wire", r.stdout, re.M), r.stdout


def _figures(monkeypatch: pytest.MonkeyPatch, run: Any, tmp_path: Path) -> dict[str, Any]:
    """winding.png's and wire.png's figures, kept as they are saved (drawn in this process)."""
    from winder.analysis.figures import analysis as figs
    from winder.analysis.metrics import analyze, digest_run

    kept: dict[str, Any] = {}
    real = figs._save

    def keep(fig: Any, path: Path) -> Path:
        kept[path.name] = fig
        return real(fig, path)

    monkeypatch.setattr(figs, "_save", keep)
    d = digest_run(run)
    figs._winding(run, analyze(run, digested=d), d, tmp_path)
    keep(figs.wire_figure(run, d), tmp_path / "wire.png")
    return kept


def test_every_panel_of_winding_png_has_an_x_label_and_the_peak_panel_its_own_speed(
    ortho: Path, monkeypatch: pytest.MonkeyPatch, tmp_path: Path
) -> None:
    run = read_run(ortho)
    kept = _figures(monkeypatch, run, tmp_path)
    for ax in kept["winding.png"].axes:
        assert ax.get_xlabel(), f"a panel of winding.png has no x label: {ax.get_title()!r}"
        assert any(t.get_text() for t in ax.get_xticklabels()), ax.get_title()
    [zoom] = [ax for ax in kept["wire.png"].axes if ax.get_title(loc="left").startswith("around the peak")]
    title = zoom.get_title(loc="left")
    num = r"([0-9]+(?:\.[0-9]+)?(?:e[+-]?[0-9]+)?)"
    found = re.search(rf"{num} turns of the flyer at {num}(?:\.\.{num})? rad/s", title)
    assert found, title
    # the speeds the flyer had over the panel's time, from the recorded joint samples
    t = zoom.lines[-1].get_xdata()
    st = run.states
    fork = AXES.index("fork")
    inside = (st.t >= t.min()) & (st.t <= t.max())
    speed = np.abs(st.vel[inside, fork])
    slow, fast = float(found[2]), float(found[3] or found[2])
    assert math.isclose(fast, speed.max(), rel_tol=5e-3), (title, speed.max())
    assert math.isclose(slow, speed.min(), rel_tol=5e-3, abs_tol=1e-3) or found[3] is None, (
        title,
        speed.min(),
    )
    turned = abs(np.interp(t.max(), st.t, st.pos[:, fork]) - np.interp(t.min(), st.t, st.pos[:, fork]))
    assert math.isclose(float(found[1]), turned / (2 * math.pi), rel_tol=0.02), (title, turned)


def test_a_drivers_read_back_is_not_differentiated_as_motion(tmp_path: Path) -> None:
    """A real mock driver's run: `winder analyze` gives the axes' velocity,
    leaves their acceleration and jerk out and says why."""
    from support.domains import next_domain, release_domain

    from winder.procs import popen

    domain = next_domain()
    env = {**os.environ, "ROS_DOMAIN_ID": str(domain), "ROS_AUTOMATIC_DISCOVERY_RANGE": "LOCALHOST"}
    bags = tmp_path / "bags"
    job = tmp_path / "tiny.yaml"
    job.write_text(
        "interp_node:\n  ros__parameters:\n    job_id: tiny\n    turns_per_layer: 4\n    layers: 1\n"
        "    poles: 1\n    fork_steps_per_rev: 512\n"
    )
    bin_ = Path(sys.executable).parent
    nodes = [
        popen(
            [sys.executable, "-m", "winder.ros.mock_backend", "--ros-args", "-p", f"bag_dir:={bags}"], env=env
        ),
        popen([str(bin_ / "profile_node")], env=env),
        popen([str(bin_ / "interp_node"), "--ros-args", "-p", "autostart:=false"], env=env),
    ]
    try:
        r = subprocess.run(
            [str(WINDER), "ctl", "start", str(job), "--wait", "--timeout", "60"],
            env=env, capture_output=True, text=True, timeout=300,
        )  # fmt: skip
        assert r.returncode == 0, r.stdout + r.stderr
    finally:
        for p in nodes:
            p.send_signal(2)
        for p in nodes:
            p.wait(30)
        release_domain(domain)
    [bag] = bags_in(bags)
    assert read_run(bag).sim_config is None  # a hardware consumer: no motor model
    r = subprocess.run([str(WINDER), "analyze", str(bag)], capture_output=True, text=True, timeout=180)
    assert r.returncode == 0, r.stderr
    rows = dict(
        re.split(r"\s{2,}", ln, maxsplit=1) for ln in r.stdout.splitlines() if re.match(r"\w+: peak", ln)
    )
    assert rows["fork: peak a cmd | axis"].split(" | ")[1].startswith("- "), r.stdout
    assert rows["fork: peak jerk cmd | axis"].split(" | ")[1].startswith("- "), r.stdout
    assert float(rows["fork: peak v cmd | axis"].split(" | ")[1].split()[0]) > 0, r.stdout
    assert "acceleration and jerk not measured" in r.stdout and "read-back" in r.stdout, r.stdout
