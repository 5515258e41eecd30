"""Commands to a running cell from outside it (``winder ctl``): one service
call, with the reply's message, or the reason there was none."""

from __future__ import annotations

import time
from typing import Any

__all__ = ["set_parameter", "trigger"]


def _call(srv_type: Any, service: str, request: Any, timeout: float) -> tuple[Any, str]:
    """One call of ``service`` on the graph of this process' ROS_DOMAIN_ID,
    from a node of its own: (the reply, "") or (None, why there was none
    within ``timeout`` s)."""
    import rclpy

    from winder.ros.dds import use_profile

    use_profile()
    rclpy.init(args=[])
    node = rclpy.create_node("winder_ctl")
    try:
        client = node.create_client(srv_type, service)
        deadline = time.monotonic() + timeout
        while not client.service_is_ready():
            if time.monotonic() > deadline:
                why = f"no service {service} within {timeout:g} s (is the cell running, on this domain?)"
                return None, why
            rclpy.spin_once(node, timeout_sec=0.1)
        future = client.call_async(request)
        while not future.done():
            if time.monotonic() > deadline:
                return None, f"{service}: no reply within {timeout:g} s"
            rclpy.spin_once(node, timeout_sec=0.1)
        return future.result(), ""
    finally:
        node.destroy_node()
        rclpy.try_shutdown()


def trigger(service: str, timeout: float = 10.0) -> tuple[bool, str]:
    """Call the std_srvs/Trigger ``service``; (success, message). No service
    within ``timeout`` s is (False, why)."""
    from std_srvs.srv import Trigger

    reply, why = _call(Trigger, service, Trigger.Request(), timeout)
    if reply is None:
        return False, why
    return bool(reply.success), str(reply.message)


def set_parameter(node: str, name: str, value: float, timeout: float = 10.0) -> tuple[bool, str]:
    """Set the double parameter ``name`` of the node ``node`` (its fully
    qualified name) through its ``set_parameters`` service; (success, the
    node's reason or a confirmation)."""
    from rcl_interfaces.msg import Parameter, ParameterType, ParameterValue
    from rcl_interfaces.srv import SetParameters

    value_msg = ParameterValue(type=ParameterType.PARAMETER_DOUBLE, double_value=float(value))
    request = SetParameters.Request(parameters=[Parameter(name=name, value=value_msg)])
    reply, why = _call(SetParameters, f"{node}/set_parameters", request, timeout)
    if reply is None:
        return False, why
    result = reply.results[0]
    if not result.successful:
        return False, result.reason or f"{name} refused"
    return True, f"{node}: {name} = {value:g}"
