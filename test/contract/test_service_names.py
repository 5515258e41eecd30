"""A service a setting names is checked as rcl takes it, when it is given (issue 53).

The bridge's ``homing_service`` took names of 250-300 characters (its own
pattern holds names, not their length), and ``~/home`` then failed with a
raw ``RCLError`` when it made the client ("topic length should not exceed
'255U - 8U'"). :func:`winder.contract.topics.check_service_name` holds the
rule and :func:`winder.contract.params.check_bridge` applies it with the
node's namespace at start and on every change; rclpy's own validator of a
full name is the oracle here, at the bound and beside it.
"""

from __future__ import annotations

import pytest

from winder.contract.params import BRIDGE_SPECS, check_bridge
from winder.contract.topics import MAX_NAME_LENGTH, check_service_name
from winder.spec import SpecError


@pytest.fixture(scope="module")
def rcl() -> object:
    """rclpy's name validators (no context, no domain: rcl's C functions)."""
    pytest.importorskip("rclpy")
    from rclpy.impl.implementation_singleton import rclpy_implementation

    return rclpy_implementation


def valid(rcl: object, full: str) -> bool:
    return rcl.rclpy_get_validation_error_for_full_topic_name(full) is None  # type: ignore[attr-defined, no-any-return]


BRIDGE = {**{name: spec.default for name, spec in BRIDGE_SPECS.items()}, "record": False}


@pytest.mark.parametrize("namespace", ["/", "/cell1", "/plant/line_2/cell1"])
def test_a_relative_homing_service_is_bounded_in_the_bridge_s_namespace(namespace: str, rcl: object) -> None:
    base = namespace.rstrip("/")
    most = MAX_NAME_LENGTH - len(base) - 1
    at_bound = "h" * most
    assert valid(rcl, f"{base}/{at_bound}") and not valid(rcl, f"{base}/{at_bound}h")
    check_bridge({**BRIDGE, "homing_service": at_bound}, namespace=namespace)
    with pytest.raises(SpecError) as err:
        check_bridge({**BRIDGE, "homing_service": at_bound + "h"}, namespace=namespace)
    text = str(err.value)
    assert "\n" not in text and len(text) < 400, text
    assert text.startswith("homing_service='hhhh") and f"({most + 1} characters) is invalid" in text
    assert f"at most {most} characters" in text and f"{MAX_NAME_LENGTH} characters ROS allows" in text


@pytest.mark.parametrize("length", [250, 300])
def test_the_names_of_the_issue_are_refused(length: int) -> None:
    for name in ("s" * length, "/" + "s" * (length - 1), "homing/" + "s" * (length - 7)):
        with pytest.raises(SpecError, match=r"^homing_service='.*is invalid: its full name"):
            check_bridge({**BRIDGE, "homing_service": name}, namespace="/cell1")


def test_a_fully_qualified_homing_service_is_bounded_whatever_the_namespace(rcl: object) -> None:
    name = "/" + "d" * (MAX_NAME_LENGTH - 1)
    assert valid(rcl, name) and not valid(rcl, name + "d")
    deep = "/" + "n" * 200  # a relative name of that length would not fit here
    assert check_service_name("homing_service", name, deep) == name
    with pytest.raises(
        ValueError, match=f"ROS allows a name; it may have at most {MAX_NAME_LENGTH} characters"
    ):
        check_service_name("homing_service", name + "d", deep)


def test_without_its_namespace_the_check_is_the_table_s() -> None:
    """A node passes its namespace; a table check alone (a job file) cannot know it."""
    check_bridge({**BRIDGE, "homing_service": "s" * 300})
    # none: the axes are referenced where they stand
    check_bridge({**BRIDGE, "homing_service": ""}, namespace="/cell1")


@pytest.mark.parametrize(
    ("value", "why"), [("a//b", "empty name"), ("home/", "empty name"), ("1home", "'1home'")]
)
def test_a_service_name_has_rcl_s_tokens(value: str, why: str) -> None:
    with pytest.raises(ValueError, match=f"^homing_service={value!r} is invalid.*{why}"):
        check_service_name("homing_service", value, "/cell1")
