"""A probe node's dealings with a running cell: spinning it, the statuses
it hears, and the parameter and start services it calls (asking again where a DDS service
reply can be lost)."""

from __future__ import annotations

import time
from typing import Any

from support import wait


def heard_diagnostics(ros: Any) -> list[tuple[str, str, dict[str, str]]]:
    """Every DiagnosticStatus the probe node hears from now on: (name, message, values)."""
    from diagnostic_msgs.msg import DiagnosticArray

    seen: list[tuple[str, str, dict[str, str]]] = []
    ros.create_subscription(
        DiagnosticArray,
        "/diagnostics",
        lambda m: seen.extend((s.name, s.message, {kv.key: kv.value for kv in s.values}) for s in m.status),
        100,
    )
    return seen


def under_way(seen: list[tuple[str, str, dict[str, str]]], namespace: str = "") -> dict[str, str] | None:
    """The last job status of :func:`heard_diagnostics` in which the step
    consumer of the cell in ``namespace`` says its run is running with steps
    executed (a run mid-job), or None."""
    from winder.contract.topics import has_role

    on = [
        v
        for n, _, v in seen
        if has_role(n, v, "consumer", namespace)
        and v.get("state") == "running"
        and v.get("steps_done", "0") != "0"
    ]
    return on[-1] if on else None


def spin_until(node: Any, cond: Any, timeout: float, what: str, heard: Any = None) -> Any:
    """Spin ``node`` until ``cond()`` is true, or fail naming ``what`` (:func:`support.wait.spin_until`)."""
    return wait.spin_until(node, cond, timeout, what, heard=heard)


def ros_spin(node: Any, seconds: float) -> None:
    """Spin the probe node for ``seconds`` (:func:`support.wait.spin_for`)."""
    wait.spin_for(node, seconds)


def get_params(node: Any, target: str, names: list[str]) -> list[Any]:
    """The values of ``target``'s parameters ``names``."""
    from rclpy.parameter import parameter_value_to_python

    return [parameter_value_to_python(v) for v in get_param_values(node, target, names)]


def get_param_values(node: Any, target: str, names: list[str]) -> list[Any]:
    """``target``'s parameters ``names`` as ``rcl_interfaces/ParameterValue``
    messages (their type with them)."""
    from rcl_interfaces.srv import GetParameters

    client = node.create_client(GetParameters, f"/{target}/get_parameters")
    spin_until(node, client.service_is_ready, 30, f"{target}/get_parameters")
    # a DDS service reply can be lost while the reply topic still matches
    # (docs/RELIABILITY.md): ask again after 10 s, three times at most
    for attempt in range(3):
        future = client.call_async(GetParameters.Request(names=names))
        try:
            spin_until(node, future.done, 10, "get_parameters reply")
            break
        except AssertionError:
            client.remove_pending_request(future)
            if attempt == 2:
                raise
    node.destroy_client(client)
    return list(future.result().values)


def start_run(node: Any, values: dict[str, Any]) -> Any:
    """Call /interp_node/start_run with ``values``, asking again while the cell
    is still connecting ("not ready"); the SetParametersResult."""
    from rcl_interfaces.srv import SetParametersAtomically
    from rclpy.parameter import Parameter

    client = node.create_client(SetParametersAtomically, "/interp_node/start_run")
    spin_until(node, client.service_is_ready, 30, "the start_run service")
    t_end = time.monotonic() + 30
    while True:
        req = SetParametersAtomically.Request()
        req.parameters = [Parameter(k, value=v).to_parameter_msg() for k, v in values.items()]
        future = client.call_async(req)
        try:  # a DDS service reply can be lost while its topic is still matching: ask again
            spin_until(node, future.done, 5, "the start_run reply")
        except AssertionError:
            client.remove_pending_request(future)
            if time.monotonic() > t_end:
                raise
            continue
        result = future.result().result
        if result.successful or "not ready" not in result.reason or time.monotonic() > t_end:
            return result
        ros_spin(node, 0.3)


def start_job(node: Any, timeout: float = 30.0) -> Any:
    """Call /interp_node/start, asking again while the cell is still
    connecting ("not ready": the nodes' handshake on winder/ready comes after
    their services); the std_srvs/Trigger response. Not asked again on a lost
    reply: a second start could then be taken."""
    from std_srvs.srv import Trigger

    client = node.create_client(Trigger, "/interp_node/start")
    spin_until(node, client.service_is_ready, timeout, "the start service")
    t_end = time.monotonic() + timeout
    while True:
        future = client.call_async(Trigger.Request())
        spin_until(node, future.done, 30, "the start reply")
        reply = future.result()
        if reply.success or "not ready" not in reply.message or time.monotonic() > t_end:
            node.destroy_client(client)
            return reply
        ros_spin(node, 0.3)


def set_params(node: Any, target: str, values: dict[str, Any]) -> list[Any]:
    from rcl_interfaces.srv import SetParameters
    from rclpy.parameter import Parameter

    client = node.create_client(SetParameters, f"/{target}/set_parameters")
    spin_until(node, client.service_is_ready, 30, f"{target}/set_parameters")
    req = SetParameters.Request(
        parameters=[Parameter(k, value=v).to_parameter_msg() for k, v in values.items()]
    )
    # DDS services can drop a reply while the response topic is still matching
    # (service_is_ready() only sees the request side): ask again
    for _ in range(6):
        fut = client.call_async(req)
        try:
            spin_until(node, fut.done, 5, "set_parameters reply")
        except AssertionError:
            client.remove_pending_request(fut)
            continue
        return list(fut.result().results)
    raise AssertionError(f"no reply from {target}/set_parameters in 30 s")


def ready_states(ros: Any) -> dict[str, str]:
    """What the probe hears on winder/ready (latched), role -> state."""
    from diagnostic_msgs.msg import KeyValue
    from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy

    states: dict[str, str] = {}
    latched = QoSProfile(
        depth=10, reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.TRANSIENT_LOCAL
    )
    ros.create_subscription(KeyValue, "/winder/ready", lambda m: states.__setitem__(m.key, m.value), latched)
    return states
