"""winder.record.capability: Cm and Cmk of a recipe's parts, and one-sided tolerances.

The oracle is a plain loop over the values in exact rational arithmetic
(``fractions.Fraction``): the mean and the sample variance as their
definitions write them, with no rounding until the last square root, so the
comparison measures the module's rounding alone. Closed-form cases give
values whose mean, standard deviation and band are known by hand. The
series are read from an index written as a consumer writes it.
"""

from __future__ import annotations

import json
import math
from fractions import Fraction
from pathlib import Path

import pytest
from hypothesis import assume, given, settings
from hypothesis import strategies as st

from winder.errors import BadInputError
from winder.motion.tolerances import check_tolerances, parse_tolerances, tolerance_text, verdict
from winder.record.capability import MIN_PARTS, NOT_CHARACTERISTICS, capability, mean_sd, series, unit_of
from winder.record.parts import PartEnd, PartIndex, PartStart


def oracle(
    values: list[float], lsl: float | None, usl: float | None
) -> tuple[float, float, float | None, float]:
    """Mean, sd, Cm and Cmk by the definitions, summed in a plain loop, exactly."""
    total = Fraction(0)
    for x in values:
        total += Fraction(x)
    mean = total / len(values)
    squares = Fraction(0)
    for x in values:
        squares += (Fraction(x) - mean) ** 2
    sd = math.sqrt(squares / (len(values) - 1))
    cm = None if lsl is None or usl is None else float((Fraction(usl) - Fraction(lsl)) / (6 * Fraction(sd)))
    sides = [Fraction(usl) - mean] if usl is not None else []
    sides += [mean - Fraction(lsl)] if lsl is not None else []
    return float(mean), sd, cm, float(min(sides) / (3 * Fraction(sd)))


def wide() -> st.SearchStrategy[float]:
    """Values from 1e-9 to 1e9 in size, either sign, and zero (their squares stay normal floats)."""
    return st.floats(-1e9, 1e9, allow_nan=False, allow_subnormal=False).map(
        lambda x: 0.0 if abs(x) < 1e-9 else x
    )


@settings(max_examples=400, deadline=None)
@given(
    values=st.lists(wide(), min_size=MIN_PARTS, max_size=300),
    scale=st.sampled_from([1.0, math.sqrt(0.5) * 1e-6, math.pi * 1e-12]),  # full mantissas, 1e9 +- 3e-3
    offset=st.sampled_from([0.0, 1.0, -12.5, 1e6, -3e7, 1e9]),
    band=st.tuples(wide(), wide()),
    side=st.sampled_from(["both", "upper", "lower"]),
)
def test_cm_and_cmk_equal_a_plain_loop_oracle(
    values: list[float], scale: float, offset: float, band: tuple[float, float], side: str
) -> None:
    """Values of any size, and narrow ones far from zero (down to 1e9 +- 3e-3, where a plain sum of
    floats loses the spread to 1e-7: the module must not)."""
    values = [x * scale + offset for x in values]
    assume(min(values) < max(values))  # some spread: else there is no Cm (another test)
    lo, hi = min(band) + offset, max(band) + offset
    lsl, usl = (lo if side != "upper" else None), (hi if side != "lower" else None)
    mean, sd, cm, cmk = oracle(values, lsl, usl)
    got = capability("x", values, lsl, usl)
    assert got.n == len(values) and (got.lsl, got.usl) == (lsl, usl)
    assert got.mean is not None and got.sd is not None and got.cmk is not None
    # the mean to 1e-12 of the values' size, the sd to 1e-12 of itself
    assert abs(got.mean - mean) <= 1e-12 * max(abs(v) for v in values)
    assert got.sd == pytest.approx(sd, rel=1e-12, abs=0)
    if cm is None:
        assert got.cm is None and "one-sided" in got.note
    else:
        assert got.cm == pytest.approx(cm, rel=1e-12, abs=0) and got.note == ""
    # Cmk: a limit minus the mean is as exact as the mean's rounding lets it be, so 1e-12 of the terms' size
    scale = (max(abs(v) for v in values) + max(abs(b) for b in (lsl, usl) if b is not None)) / (3 * sd)
    assert abs(got.cmk - cmk) <= 1e-12 * max(abs(cmk), scale)


def test_closed_form_cases() -> None:
    """15 parts at 9 and 15 at 11: mean 10, sd = sqrt(30/29) (30 squares of 1 over 29)."""
    values = [9.0] * 15 + [11.0] * 15
    sd = math.sqrt(30 / 29)
    centred = capability("r", values, 7.0, 13.0)
    assert centred.mean == 10.0 and centred.sd == pytest.approx(sd, rel=1e-15)
    assert centred.cm == pytest.approx(6 / (6 * sd), rel=1e-15)  # the band is 6 units: Cm = 1 / sd
    assert centred.cmk == pytest.approx(3 / (3 * sd), rel=1e-15)  # centred: Cmk = Cm
    off = capability("r", values, 8.0, 14.0)  # the same band, 1 up: the mean 2 from LSL, 4 from USL
    assert off.cm == pytest.approx(centred.cm, rel=1e-15)
    assert off.cmk == pytest.approx(2 / (3 * sd), rel=1e-15)
    upper = capability("t", values, None, 13.0)  # one-sided: 3 above the mean
    assert upper.cm is None and upper.cmk == pytest.approx(3 / (3 * sd), rel=1e-15)
    assert upper.note == "one-sided: Cmk of the upper limit only"
    lower = capability("t", values, 4.0, None)  # 6 below it
    assert lower.cm is None and lower.cmk == pytest.approx(6 / (3 * sd), rel=1e-15)
    assert lower.note == "one-sided: Cmk of the lower limit only"
    outside = capability("r", values, 10.5, 20.0)  # the mean below LSL: Cmk negative
    assert outside.cmk == pytest.approx(-0.5 / (3 * sd), rel=1e-15)


@pytest.mark.parametrize(
    ("values", "lsl", "usl", "note"),
    [
        ([12.0] * 40, 11.5, 12.5, "no spread: every value the same"),
        ([1.0, 2.0] * 10, 0.0, 3.0, f"20 values, fewer than {MIN_PARTS}"),
        ([1.0, 2.0] * 20, None, None, "no tolerance"),
        ([], 0.0, 1.0, "not recorded"),
    ],
)
def test_no_figure_where_none_can_be_given(
    values: list[float], lsl: float | None, usl: float | None, note: str
) -> None:
    got = capability("x", values, lsl, usl)
    assert (got.cm, got.cmk, got.note, got.n) == (None, None, note, len(values))


def test_a_constant_series_has_its_value_for_mean_and_zero_sd() -> None:
    assert mean_sd([0.1] * 3) == (0.1, 0.0)  # fsum(0.1 * 3) / 3 is not 0.1
    assert mean_sd([7.0]) == (7.0, None)
    with pytest.raises(ValueError, match="no values"):
        mean_sd([])


# -- the series of an index ----------------------------------------------------------------------

T0 = 1_795_911_156_000_000_000


def part(index: PartIndex, n: int, *, measured: float | None, report: dict[str, str]) -> None:
    run = f"rw400_20261129_{n:09d}_1"
    part_id = index.begin(
        PartStart(
            run_id=run,
            job_id="rw400",
            recipe_sha256="ab" * 32,
            recipe_source="job_file",
            software_version="0.1.0",
            consumer="sim_node",
            simulated=True,
            steps_total=100,
            started_ns=T0 + n * 10**9,
            turns_commanded=40,
            resistance_predicted_ohm=12.0,
        )
    )
    index.close(
        part_id, PartEnd(T0 + n * 10**9 + 5 * 10**8, {"state": "done", "steps_done": "100", **report})
    )
    if measured is not None:
        index.measure(part_id, measured)


def test_series_are_the_parts_values_in_order(tmp_path: Path) -> None:
    index = PartIndex(tmp_path / "parts.sqlite")
    part(index, 0, measured=11.9, report={"tension_peak_n": "2.5", "wire_taken_m": "31.0", "gaps": "0"})
    part(index, 1, measured=None, report={"tension_peak_n": "2.7", "max_tracking_error_steps": "0.4"})
    part(index, 2, measured=12.1, report={"tension_peak_n": "nan", "gaps": "1", "note": "words"})
    got = series(index.parts())
    assert got["resistance_ohm"] == [11.9, None, 12.1]  # measured only: the prediction is no sample
    assert got["tension_max_n"] == [2.5, 2.7, None]  # the column; the report's name is not a second series
    assert got["wire_length_m"] == [31.0, None, None]
    assert got["max_tracking_error_steps"] == [None, 0.4, None]  # a report key, where reported
    assert got["gaps"] == [0.0, None, 1.0]
    assert got["cycle_time_s"] == [0.5, 0.5, 0.5]
    assert "turns_error" not in got  # no part counted its turns
    assert not set(got) & NOT_CHARACTERISTICS
    assert "note" not in got and "tension_peak_n" not in got and "wire_taken_m" not in got


@pytest.mark.parametrize(
    ("name", "unit"),
    [
        ("resistance_ohm", "Ω"),
        ("tension_max_n", "N"),
        ("cycle_time_s", "s"),
        ("wire_length_m", "m"),
        ("max_tracking_error_steps", "steps"),
        ("steps_done", "steps"),
        ("turns_error", "turns"),
        ("breaks", "count"),
        ("real_time_factor", ""),
    ],
)
def test_a_scalars_unit_is_read_from_its_name(name: str, unit: str) -> None:
    assert unit_of(name) == unit


# -- one-sided tolerances -------------------------------------------------------------------------


def test_a_tolerance_may_be_open_at_one_end() -> None:
    assert check_tolerances({"tension_max_n": [None, 3.0], "wire_length_m": [30, None]}) == {
        "tension_max_n": (None, 3.0),
        "wire_length_m": (30.0, None),
    }
    assert parse_tolerances('{"tension_max_n": [null, 3]}') == {"tension_max_n": (None, 3.0)}
    assert check_tolerances({"tension_max_n": [-math.inf, 3.0], "x": [0, math.inf]}) == {
        "tension_max_n": (None, 3.0),
        "x": (0.0, None),
    }
    assert (tolerance_text(None, 3.0), tolerance_text(30.0, None)) == ("(-inf, 3]", "[30, inf)")
    tolerances = {"tension_max_n": (None, 3.0)}
    assert verdict("done", {"tension_max_n": -5.0}, tolerances) == ("ok", [])
    assert verdict("done", {"tension_max_n": 3.5}, tolerances) == (
        "nok",
        ["tension_max_n 3.5 outside (-inf, 3]"],
    )
    with pytest.raises(BadInputError, match=r"tension_max_n=\[null, null\] is invalid.*one end open"):
        check_tolerances({"tension_max_n": [None, None]})


def test_a_job_files_one_sided_tolerance_reaches_the_part(tmp_path: Path) -> None:
    from winder.contract.jobfile import load_job_file_hashed
    from winder.contract.stream import describe_job, parse_job_description
    from winder.motion.job import Job
    from winder.record.parts import part_start

    path = tmp_path / "one_sided.yaml"
    path.write_text(
        "interp_node:\n  ros__parameters:\n    job_id: one\n    layers: 1\n    poles: 1\n"
        "    tolerances:\n      tension_max_n: [-.inf, 3.0]\n      cycle_time_s: [1, .inf]\n"
    )
    doc, sha = load_job_file_hashed(path)
    job = Job.from_dict(doc["interp_node"])
    plan = parse_job_description(describe_job(job, "one_20261129_000000000_1", job_file_sha256=sha))
    started = part_start(
        plan, consumer="sim_node", simulated=True, software_version="0.1.0", started_ns=1, bag=""
    )
    assert started.tolerances == {"tension_max_n": (None, 3.0), "cycle_time_s": (1.0, None)}
    index = PartIndex(tmp_path / "parts.sqlite")
    part_id = index.begin(started)
    row = index.close(part_id, PartEnd(5 * 10**8 + 1, {"state": "done", "tension_peak_n": "3.2"}))
    assert json.loads(row["reasons"]) == [
        "tension_max_n 3.2 outside (-inf, 3]",
        "cycle_time_s 0.5 outside [1, inf)",
    ]
