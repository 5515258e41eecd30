"""The coil as wound (winder.analysis.wound, ``winder analyze``): where each
turn was laid by the simulated axes of a real run, against the helical
lay's formulas written again here, and the defects of a run whose feed
motor loses steps found at the turn where the feed first left its command."""

from __future__ import annotations

import json
import math
import subprocess
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from conftest import BIN, rosbags_read
from support.bags import job_doc, joint_arrays

from winder.analysis.wound import as_wound
from winder.record.reader import read_run

pytestmark = pytest.mark.ros


def test_a_clean_run_lays_every_turn_in_its_place(bag: Any) -> None:
    path = bag("lin2k")
    wound = as_wound(read_run(path))
    assert wound is not None
    job = job_doc(rosbags_read(path)["/winder/job"][0][1])["job"]
    d, n, layers, poles = job["wire_diameter"], job["turns_per_layer"], job["layers"], job["poles"]
    assert wound.turns_per_layer() == [[n] * layers] * poles
    assert wound.defects == []
    for turn in wound.turns:
        k = turn.turn - 1
        # helical: odd layers from the coil's start flange (where its first layer starts),
        # even layers back; centres d apart, the first at d/2 from the flange
        expected = (k + 0.5) * d if turn.layer % 2 == 1 else (n - k - 0.5) * d
        assert math.isclose(turn.intended_m, expected, abs_tol=job["feed_step"])
        assert abs(turn.axial_m - expected) < 0.1 * d, turn
        assert math.isclose(turn.radial_m, d / 2 + (turn.layer - 1) * d, rel_tol=1e-12)
    assert max(lay.max_axial_error_m for lay in wound.layers) < 0.1 * d


def test_a_feed_that_loses_steps_is_found_where_it_happened(bag: Any) -> None:
    path = bag("feedslip")
    run = read_run(path)
    wound = as_wound(run)
    assert wound is not None
    ref = rosbags_read(path)
    report = [
        {kv.key: kv.value for kv in st.values}
        for _, arr in ref["/diagnostics"]
        for st in arr.status
        if st.name.endswith("sim_node: job")
    ][-1]
    assert int(report["lost_steps"]) > 0
    assert wound.defects, "a run that lost feed steps shows no defect"
    # where the feed first left its command by more than the tolerance, from the raw samples
    t_cmd, cmd, _ = joint_arrays(ref["/winder/joint_commands"])
    t_act, act, _ = joint_arrays(ref["/winder/joint_states"])
    assert np.array_equal(t_cmd, t_act)
    # where the feed first left its command for good: beyond a bound for a whole turn of
    # the flyer from then on (a lag while it accelerates is no loss). The command leads the
    # flyer's own lag a little, so the loss is bracketed by half and twice the tolerance
    dev = np.abs(act[:, 0] - cmd[:, 0])

    def lasting(bound: float) -> float:
        off = dev > bound
        for i in np.flatnonzero(off):
            if off[i : int(np.searchsorted(act[:, 1], act[i, 1] + 2 * math.pi)) + 1].all():
                return float(act[i, 1])
        raise AssertionError(f"the feed never left its command by {bound} m for good: the run is no test")

    early, late = lasting(wound.tolerance_m / 2), lasting(2 * wound.tolerance_m)
    job = job_doc(ref["/winder/job"][0][1])["job"]
    spr = job["fork_steps_per_rev"]
    first = wound.defects[0]
    # the flyer angle at the middle of the first faulty turn (one coil, the fork turning forward)
    turns_before = (first.layer - 1) * job["turns_per_layer"] + first.turn - 1
    mid = (turns_before + 0.5) * 2 * math.pi
    # it is the turn the loss happened in, or the next (a turn is judged at its middle)
    turns = (early / (2 * math.pi), late / (2 * math.pi))
    assert early - 2 * math.pi <= mid <= late + 2 * math.pi, (first, f"loss between turns {turns}")
    assert spr > 0
    # winder analyze says so, and --json has them under as_wound
    r = subprocess.run(
        [str(BIN / "winder"), "analyze", str(path), "--no-plots", "--json"],
        capture_output=True, text=True, timeout=120, stdin=subprocess.DEVNULL,
    )  # fmt: skip
    assert r.returncode == 0, r.stderr
    doc = json.loads(r.stdout)[0]["as_wound"]
    assert doc["turns_per_layer"] == wound.turns_per_layer()
    assert len(doc["defects"]) == len(wound.defects)
    assert doc["defects"][0]["turn"] == first.turn and doc["defects"][0]["kind"] == first.kind


def test_wound_png_is_drawn(bag: Any, tmp_path: Path) -> None:
    r = subprocess.run(
        [str(BIN / "winder"), "analyze", str(bag("feedslip")), "--plots-dir", str(tmp_path)],
        capture_output=True, text=True, timeout=180, stdin=subprocess.DEVNULL,
    )  # fmt: skip
    assert r.returncode == 0, r.stderr
    png = tmp_path / "wound.png"
    assert png.stat().st_size > 10_000 and png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert "as wound: defects" in r.stdout and "first:" in r.stdout, r.stdout
