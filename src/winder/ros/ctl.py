"""Commands to a running cell from outside it (``winder ctl``): one service
call, with the reply's message, or the reason there was none."""

from __future__ import annotations

import time

__all__ = ["set_parameter", "trigger"]


def trigger(service: str, timeout: float = 10.0) -> tuple[bool, str]:
    """Call the std_srvs/Trigger ``service`` on the graph of this process'
    ROS_DOMAIN_ID; (success, message). No service within ``timeout`` s is
    (False, why)."""
    import rclpy
    from std_srvs.srv import Trigger

    rclpy.init(args=[])
    node = rclpy.create_node("winder_ctl")
    try:
        client = node.create_client(Trigger, service)
        deadline = time.monotonic() + timeout
        while not client.service_is_ready():
            if time.monotonic() > deadline:
                return (
                    False,
                    f"no service {service} within {timeout:g} s (is the cell running, on this domain?)",
                )
            rclpy.spin_once(node, timeout_sec=0.1)
        future = client.call_async(Trigger.Request())
        while not future.done():
            if time.monotonic() > deadline:
                return False, f"{service}: no reply within {timeout:g} s"
            rclpy.spin_once(node, timeout_sec=0.1)
        reply = future.result()
        return bool(reply.success), str(reply.message)
    finally:
        node.destroy_node()
        rclpy.try_shutdown()


def set_parameter(node: str, name: str, value: float, timeout: float = 10.0) -> tuple[bool, str]:
    """Set the double parameter ``name`` of the node ``node`` (its fully
    qualified name) through its ``set_parameters`` service; (success, the
    node's reason or a confirmation)."""
    import rclpy
    from rcl_interfaces.msg import Parameter, ParameterType, ParameterValue
    from rcl_interfaces.srv import SetParameters

    rclpy.init(args=[])
    ctl = rclpy.create_node("winder_ctl")
    service = f"{node}/set_parameters"
    try:
        client = ctl.create_client(SetParameters, service)
        deadline = time.monotonic() + timeout
        while not client.service_is_ready():
            if time.monotonic() > deadline:
                return (
                    False,
                    f"no service {service} within {timeout:g} s (is the cell running, on this domain?)",
                )
            rclpy.spin_once(ctl, timeout_sec=0.1)
        value_msg = ParameterValue(type=ParameterType.PARAMETER_DOUBLE, double_value=float(value))
        future = client.call_async(SetParameters.Request(parameters=[Parameter(name=name, value=value_msg)]))
        while not future.done():
            if time.monotonic() > deadline:
                return False, f"{service}: no reply within {timeout:g} s"
            rclpy.spin_once(ctl, timeout_sec=0.1)
        result = future.result().results[0]
        if not result.successful:
            return False, result.reason or f"{name} refused"
        return True, f"{node}: {name} = {value:g}"
    finally:
        ctl.destroy_node()
        rclpy.try_shutdown()
