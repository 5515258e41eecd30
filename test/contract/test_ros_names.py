"""Names ROS would refuse are refused first, in one line (issue 41).

A 300-character ``--namespace`` ended ``winder run``, ``view``, ``play``
and ``ctl`` in rclpy's traceback; a 300-character bridge ``controller``
ended the node ("topic length should not exceed '255U - 8U'"). One checker
(:mod:`winder.contract.topics`) holds rcl's rules; rclpy's own validators
are the oracle here, at the bound and beside it.
"""

from __future__ import annotations

import pytest

from winder.contract.params import BRIDGE_SPECS, CONTROLLER_TOPICS, check_bridge
from winder.contract.topics import (
    LONGEST_NAME,
    MAX_NAME_LENGTH,
    NODE_NAMES,
    NODE_SERVICES,
    check_namespace,
    check_node_name,
    check_relative_name,
)
from winder.spec import SpecError, shorten


@pytest.fixture(scope="module")
def rcl() -> object:
    """rclpy's name validators (no context, no domain: rcl's C functions)."""
    pytest.importorskip("rclpy")
    from rclpy.impl.implementation_singleton import rclpy_implementation

    return rclpy_implementation


def one_line(exc: pytest.ExceptionInfo[BaseException]) -> str:
    text = str(exc.value)
    assert "\n" not in text and len(text) < 400, text
    return text


def test_a_300_character_namespace_is_refused_naming_the_rule() -> None:
    ns = "/" + "x" * 300
    with pytest.raises(ValueError) as err:
        check_namespace(ns)
    text = one_line(err)
    assert text.startswith("namespace='/xxxxxxxx") and "(301 characters) is invalid" in text
    assert f"{MAX_NAME_LENGTH} characters" in text and LONGEST_NAME in text


def test_the_longest_namespace_allowed_is_the_longest_ros_takes_for_every_name_of_the_cell(
    rcl: object,
) -> None:
    most = MAX_NAME_LENGTH - 1 - len(LONGEST_NAME)
    ns = "/" + "n" * (most - 1)
    assert check_namespace(ns) == ns
    names = [f"{node}/{service}" for node in NODE_NAMES for service in NODE_SERVICES]
    assert LONGEST_NAME in names or len(LONGEST_NAME) >= max(map(len, names))
    assert rcl.rclpy_get_validation_error_for_namespace(ns) is None  # type: ignore[attr-defined]
    for name in names:
        assert rcl.rclpy_get_validation_error_for_full_topic_name(f"{ns}/{name}") is None, name  # type: ignore[attr-defined]
    longer = ns + "n"
    with pytest.raises(ValueError, match=f"{most + 1} characters, at most {most}"):
        check_namespace(longer)
    assert rcl.rclpy_get_validation_error_for_full_topic_name(f"{longer}/{LONGEST_NAME}") is not None  # type: ignore[attr-defined]


@pytest.mark.parametrize(
    "ns", ["a b", "1cell", "/cell//x", "/cell1/", "cell-1", "/ä", "/" + "x" * 120 + "-", "//"]
)
def test_what_rcl_refuses_in_a_namespace_is_refused(ns: str, rcl: object) -> None:
    with pytest.raises(ValueError) as err:
        check_namespace(ns)
    assert one_line(err).startswith(f"namespace={shorten(ns)} is invalid")
    absolute = ns if ns.startswith("/") else "/" + ns
    assert rcl.rclpy_get_validation_error_for_namespace(absolute) is not None  # type: ignore[attr-defined]


@pytest.mark.parametrize("ns", ["", "/", "/cell1", "cell1", "/_a/B2/c_3"])
def test_what_rcl_takes_is_taken(ns: str, rcl: object) -> None:
    out = check_namespace(ns)
    assert out in ("", "/" + ns.strip("/"))
    assert rcl.rclpy_get_validation_error_for_namespace(out or "/") is None  # type: ignore[attr-defined]


def test_the_option_is_named() -> None:
    with pytest.raises(ValueError, match=r"^the recorded namespace='/a b' is invalid"):
        check_namespace("/a b", "the recorded namespace")


def test_a_controller_past_the_length_of_a_topic_name_is_refused(rcl: object) -> None:
    """The bridge's ``controller`` names ``<controller>/commands`` and
    ``<controller>/joint_trajectory`` in the bridge's namespace."""
    values = {name: spec.default for name, spec in BRIDGE_SPECS.items()}
    values.update(record=False, controller="f" * 300)
    with pytest.raises(SpecError) as err:
        check_bridge(values, namespace="/cell1")
    text = one_line(err)
    assert text.startswith("controller='ffff") and "(300 characters) is invalid" in text
    most = MAX_NAME_LENGTH - len("/cell1/") - len("/joint_trajectory")
    assert f"at most {most} characters" in text
    check_bridge({**values, "controller": "f" * most}, namespace="/cell1")
    for tail in CONTROLLER_TOPICS:
        assert rcl.rclpy_get_validation_error_for_full_topic_name(f"/cell1/{'f' * most}{tail}") is None  # type: ignore[attr-defined]
    assert rcl.rclpy_get_validation_error_for_full_topic_name(f"/cell1/{'f' * (most + 1)}/joint_trajectory")  # type: ignore[attr-defined]
    with pytest.raises(SpecError):
        check_bridge({**values, "controller": "f" * (most + 1)}, namespace="/cell1")
    check_bridge(values)  # without its namespace the check is the table's (a node passes it)


@pytest.mark.parametrize(
    ("value", "why"), [("a//b", "empty name"), ("1a", "'1a'"), ("a-b", "'a-b'"), ("", "")]
)
def test_a_relative_name_has_rcl_s_tokens(value: str, why: str) -> None:
    with pytest.raises(ValueError, match=f"^controller={value!r} is invalid.*{why}"):
        check_relative_name("controller", value)


def test_a_node_named_on_the_command_line_is_checked_whole(rcl: object) -> None:
    assert check_node_name("interp_node", "/cell1") == "/cell1/interp_node"
    assert check_node_name("/other/axes", "/cell1") == "/other/axes"
    assert check_node_name("sim_node", "") == "/sim_node"
    service = max(NODE_SERVICES, key=len)
    most = MAX_NAME_LENGTH - 1 - len(service)
    name = "/" + "n" * (most - 1)
    assert check_node_name(name) == name
    assert rcl.rclpy_get_validation_error_for_full_topic_name(f"{name}/{service}") is None  # type: ignore[attr-defined]
    with pytest.raises(ValueError) as err:
        check_node_name(name + "n")
    assert one_line(err).startswith("node='/nnnn") and f"at most {most}" in str(err.value)
    for bad in ("a-b", "/x//y", "1node", ""):
        with pytest.raises(ValueError, match=r"^node=.* is invalid"):
            check_node_name(bad, "/cell1")
