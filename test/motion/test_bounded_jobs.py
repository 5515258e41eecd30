"""Every job setting is bounded before any work is sized from it (issue 41).

* ``turns_per_layer: auto`` resolves to the turns that fit the window and is
  held to ``turns_per_layer``'s own range, before the coil is laid out (10 m
  of 10 um wire: 10^6 turns a layer took 8.5 minutes and 1.5 GB to check);
* a job's straight moves (an orthocyclic layer is a cam of two a turn) are
  counted from its turns and bounded before it is laid out;
* a coil whose layer holds no turn (a window narrower than the lay needs) is
  refused in the words of its overflow, never an IndexError;
* a job is laid out once; a cam is walked chunk by chunk without indexing
  it again for every chunk.

The "before" is shown, not timed: the laying out is replaced by a function
that fails, and the refusal must come first.
"""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import winder.motion.interp as interp
import winder.motion.job as job_module
from winder.contract.params import check_interp
from winder.motion.interp import interpolate, interpolate_pieces, pieces_mismatch
from winder.motion.job import CAM_PIECES, FIELD_SPECS, MAX_PIECES, Job, JobError


@pytest.fixture
def no_layout(monkeypatch: pytest.MonkeyPatch) -> None:
    """Laying a coil out or a job's moves fails the test: a refusal must come first."""

    def forbidden(*_args: object, **_kwargs: object) -> None:
        raise AssertionError("the job was laid out before it was bounded")

    monkeypatch.setattr(job_module, "winding", forbidden)
    monkeypatch.setattr(Job, "_lay_out", forbidden)


@pytest.fixture
def no_moves(monkeypatch: pytest.MonkeyPatch) -> None:
    """Laying a job out in moves fails the test (the coil's layers, one
    object a layer, are laid out: its turn counts are what is bounded)."""

    def forbidden(*_args: object, **_kwargs: object) -> None:
        raise AssertionError("the job was laid out in moves before it was bounded")

    monkeypatch.setattr(Job, "_lay_out", forbidden)


@pytest.mark.parametrize("lay", ["helical", "orthocyclic"])
def test_auto_turns_past_the_limit_are_refused_before_the_coil_is_laid_out(lay: str, no_layout: None) -> None:
    with pytest.raises(JobError) as err:
        Job(turns_per_layer="auto", window_width=10.0, wire_diameter=1e-5, lay=lay)
    text = str(err.value)
    assert "\n" not in text
    assert text.startswith("turns_per_layer=auto is invalid: 1000000 turns"), text
    assert "bobbin.window_width=10 m" in text and "[1, 100000]" in text


def test_auto_turns_in_a_coil_override_are_held_to_the_same_limit(no_layout: None) -> None:
    with pytest.raises(
        JobError, match=r"coil_overrides: turns_per_layer=auto is invalid: 1000000 turns .*\[1, 100000\]"
    ):
        Job(
            turns_per_layer=20, window_width=10.0, wire_diameter=1e-5, coil_overrides="2:turns_per_layer=auto"
        )


def test_auto_turns_at_the_limit_are_wound() -> None:
    spec = FIELD_SPECS["turns_per_layer"]
    assert spec.high == 100_000
    job = Job(turns_per_layer="auto", window_width=10.0, wire_diameter=1e-4, layers=1, poles=1)
    assert job.layer_turns == 100_000
    assert job.coil(0).turns_per_layer == 100_000


def test_auto_turns_as_the_deprecated_coil_length_name_it() -> None:
    with pytest.raises(JobError, match=r"fit a layer of coil_length=10 m"):
        Job(turns_per_layer="auto", coil_length=10.0, wire_diameter=1e-5)


ALL_MAXIMUM_ORTHOCYCLIC = {
    "turns_per_layer": 100_000,
    "layers": 1000,
    "poles": 360,
    "lay": "orthocyclic",
    "lay.crossover": 180.0,
    "feed_step": 1e-4,
}


def test_a_job_of_too_many_moves_is_refused_before_it_is_laid_out(no_moves: None) -> None:
    """The all-maximum orthocyclic job: 3.6*10^10 turns, which took hours to
    lay out; now refused from its turn counts, in one line naming them."""
    with pytest.raises(JobError) as err:
        Job.from_dict(ALL_MAXIMUM_ORTHOCYCLIC)
    text = str(err.value)
    assert "\n" not in text
    assert text.startswith("turns_per_layer=100000 x layers=1000 x poles=360 (lay=orthocyclic) is invalid")
    assert f"at most {MAX_PIECES}" in text


def test_the_interp_node_check_refuses_it_the_same_way(no_moves: None) -> None:
    values = {name: spec.default for name, spec in FIELD_SPECS.items()}
    values.update(ALL_MAXIMUM_ORTHOCYCLIC)
    with pytest.raises(JobError, match="straight moves"):
        check_interp(values)


def test_an_override_coil_is_checked_as_one_coil_not_as_a_whole_job() -> None:
    """A coil override checks that coil's layers; the job's size is the job's:
    one large coil among small ones is not refused as if every coil were it."""
    job = Job(
        turns_per_layer=10,
        layers=1,
        poles=4,
        lay="orthocyclic",
        crossover=180.0,
        crossover_law="linear",  # two moves a turn
        feed_step=1e-4,
        coil_overrides="1:turns_per_layer=2000,layers=200",  # 400 000 turns: 4 x that is past the bound
    )
    assert MAX_PIECES // 2 < 4 * 400_000 and job.straight_moves <= MAX_PIECES


@pytest.mark.parametrize(
    "fields",
    [
        {},
        {"reversal_dwell": 1.5},
        {"lay": "orthocyclic", "lay.crossover": 180.0},
        {
            "lay": "orthocyclic",
            "lay.crossover": 180.0,
            "layers": 5,
            "turns_per_layer": 7,
            "reversal_dwell": 2.0,
        },
        {"lay": "orthocyclic", "lay.crossover": 180.0, "coil_overrides": "2:layers=1;3:turns_per_layer=3"},
        {
            "lay": "orthocyclic",
            "lay.crossover": 180.0,
            "turns_per_layer": "auto",
            "bobbin.window_width": 0.05,
        },
    ],
)
@pytest.mark.parametrize("law", ["linear", "cycloidal"])
def test_the_bound_counts_at_least_the_moves_laid_out(fields: dict[str, object], law: str) -> None:
    job = Job.from_dict({**fields, "lay.crossover_law": law})
    laid = sum(len(s.pieces) for s in job.segments())
    # a cycloid's first and last pieces may hold the feed (rounded to whole steps): merged with the holds
    spare = 0 if law == "linear" or job.lay != "orthocyclic" else (CAM_PIECES - 1) * job.winding.total_turns
    assert laid <= job.straight_moves <= laid + 2 * job.poles * job.layers + spare


def test_a_job_is_laid_out_once() -> None:
    job = Job(lay="orthocyclic", crossover=180.0)
    first, second = job.segments(), job.segments()
    assert first is second and isinstance(first, tuple)  # laid out once, shared: nobody can change it


# -- a window narrower than the lay needs -------------------------------------------------------


def narrow(**extra: object) -> Job:
    """0.3 mm wire in a 0.4 mm window, orthocyclic, auto: layer 1 holds one
    turn, layer 2 (shifted by d/2) none."""
    values = {
        "lay": "orthocyclic",
        "turns_per_layer": "auto",
        "bobbin.window_width": 0.0004,
        "wire_diameter": 0.0003,
        "feed_step": 1e-5,
        "lay.crossover": 180.0,
        **extra,
    }
    return Job.from_dict(values, check_fit=False)


WORDS = "layer 2 needs 1 turn x 0.3 mm + 0.15 mm offset = 0.45 mm, the window is 0.4 mm wide"


def test_a_layer_that_holds_no_turn_is_refused_in_the_words_of_its_overflow() -> None:
    job = narrow()
    assert [layer.turns for layer in job.winding.coils[0].layers] == [1, 0]
    assert WORDS in job.winding.overflow()
    with pytest.raises(JobError, match=WORDS.replace("+", r"\+")):
        job.segments()  # was: IndexError in layer_cam
    with pytest.raises(JobError, match=WORDS.replace("+", r"\+")):
        Job.from_dict({k: getattr(job, a) for k, a in job_module.ATTRIBUTES.items()})


def test_the_interp_check_of_a_coil_that_does_not_fit_leaves_it_to_the_fit() -> None:
    """``winder check`` reads a job file with check_fit=False: the coil is
    reported, then refused for its fit; the check of the file does not lay it out."""
    values = {name: spec.default for name, spec in FIELD_SPECS.items()}
    job = narrow()
    values.update({k: getattr(job, a) for k, a in job_module.ATTRIBUTES.items()})
    check_interp({**values, "stops": "1:1"}, check_fit=False)
    with pytest.raises(JobError, match="layer 2 needs 1 turn"):
        check_interp(values)


def test_one_layer_in_that_window_is_wound() -> None:
    job = narrow(layers=1, poles=1)
    assert job.winding.fits
    assert [len(s.pieces) for s in job.segments()] == [1]


# -- a cam walked chunk by chunk -----------------------------------------------------------------


@settings(max_examples=60, deadline=None)
@given(
    st.lists(st.tuples(st.integers(-9, 9), st.integers(1, 40), st.just(0)), min_size=2, max_size=30).map(
        tuple
    ),
    st.data(),
)
def test_a_window_of_a_cam_is_its_rows(pieces: tuple[tuple[int, int, int], ...], data: st.DataObject) -> None:
    """Any window of a path of pieces is the same rows as the whole path, cut
    (the index of the pieces is made once and reused)."""
    start = np.array([5, -3, 2])
    whole = []
    at = start.copy()
    for p in pieces:
        whole.append(interpolate(at, p))
        at = at + np.asarray(p)
    full = np.concatenate(whole)
    total = full.shape[0]
    first = data.draw(st.integers(0, total))
    stop = data.draw(st.integers(first, total))
    assert np.array_equal(interpolate_pieces(start, pieces, first=first, stop=stop), full[first:stop])
    assert pieces_mismatch(start.tolist(), pieces, first, full[first:stop]) == -1
    if stop > first:
        bad = full[first:stop].copy()
        k = data.draw(st.integers(0, stop - first - 1))
        bad[k, 1] += 1
        assert pieces_mismatch(start.tolist(), pieces, first, bad) == k
    assert interp._indexed(pieces) is interp._indexed(pieces)


def test_a_list_of_pieces_is_not_taken_for_the_one_indexed_before() -> None:
    pieces = [[1, 4, 0], [0, 3, 0]]
    before = interpolate_pieces([0, 0, 0], pieces)
    pieces[1] = [2, 5, 0]  # a list may change between calls: it is indexed again
    after = interpolate_pieces([0, 0, 0], pieces)
    assert before.shape[0] == 7 and after.shape[0] == 9
    assert after[-1].tolist() == [3, 9, 0]
