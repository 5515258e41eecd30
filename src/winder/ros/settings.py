"""A node's settings as ROS parameters, declared from a winder spec table
(:mod:`winder.contract.params`): descriptors with ranges, start-up overrides
checked, run-time changes refused with the reason. Every check is the spec's
own, so a value is judged the same way in a node and in ``winder run``."""

from __future__ import annotations

import contextlib
from collections.abc import Callable
from typing import Any

from rcl_interfaces.msg import (
    FloatingPointRange,
    IntegerRange,
    ParameterDescriptor,
    ParameterType,
    SetParametersResult,
)
from rclpy.exceptions import InvalidParameterTypeException, InvalidParameterValueException
from rclpy.node import Node
from rclpy.parameter import Parameter

from winder.spec import Spec, SpecError


def descriptor(spec: Spec) -> ParameterDescriptor:
    """The ROS parameter descriptor of a winder setting. Typing is dynamic so
    that ``v_max:=3000`` (an integer) is accepted for a double; the checks in
    the set-parameters callback convert and validate every value."""
    kind = {
        bool: ParameterType.PARAMETER_BOOL,
        int: ParameterType.PARAMETER_INTEGER,
        float: ParameterType.PARAMETER_DOUBLE,
        str: ParameterType.PARAMETER_STRING,
    }[spec.kind]
    d = ParameterDescriptor(type=kind, description=spec.help(), dynamic_typing=True)
    if spec.low is not None and spec.high is not None:
        if spec.kind is float:
            d.floating_point_range = [
                FloatingPointRange(from_value=float(spec.low), to_value=float(spec.high), step=0.0)
            ]
        elif spec.kind is int:
            d.integer_range = [IntegerRange(from_value=int(spec.low), to_value=int(spec.high), step=1)]
    if spec.choices:
        d.additional_constraints = "one of: " + ", ".join(spec.choices)
    return d


#: what a node does with a value refused at start: it holds the default, and takes no job
#: until a valid value is set (it said "keeping the default" and then refused every run)
HELD = "the node holds the default"
UNTIL = " and takes no job until a valid value is set (ros2 param set, winder ctl param set)"


class Settings:
    """A node's settings declared as ROS parameters from a winder spec table.

    A bad start-up override (``--ros-args -p name:=value``) is not fatal: it is
    logged with its reason and the default is kept, and :attr:`rejected` lists
    it; run-time changes go through the same checks and are refused with the
    reason. :meth:`values` returns the current values converted to their types.
    """

    def __init__(
        self,
        node: Node,
        specs: dict[str, Spec],
        check: Callable[[dict[str, Any]], None],
    ) -> None:
        self.node = node
        self.specs = specs
        self.check = check
        self.rejected: list[str] = []
        self._values: dict[str, Any] | None = None
        log = node.get_logger()
        for name, spec in specs.items():
            try:
                node.declare_parameter(name, spec.default, descriptor(spec))
            except (InvalidParameterValueException, InvalidParameterTypeException) as exc:
                log.error(f"{self._reason_for_override(name, exc)}; {HELD} {spec.default!r}{UNTIL}")
                node.declare_parameter(name, spec.default, descriptor(spec), ignore_override=True)
                self.rejected.append(name)
                continue
            given = node.get_parameter(name).value
            try:
                value = spec.check(given)
            except SpecError as exc:
                log.error(f"{exc}; {HELD} {spec.default!r}{UNTIL}")
                node.set_parameters([Parameter(name, value=spec.default)])
                self.rejected.append(name)
                continue
            if value != given or type(value) is not type(given):  # v_max:=3000 is a double, as declared
                node.set_parameters([Parameter(name, value=value)])
        try:
            check(self.values())
        except SpecError as exc:
            log.error(f"settings rejected at start: {exc}")
            self.rejected.append(str(exc))
        # one pre-set callback, whatever is added to it: rclpy gives each of a node's
        # pre-set callbacks the list as it came and sets what they return, all of it,
        # one after the other (two callbacks: every parameter twice, the first
        # callback's version checked and set first)
        self._pre_set: list[Callable[[list[Parameter]], list[Parameter]]] = [self._as_declared]
        node.add_pre_set_parameters_callback(self._pre_set_all)
        node.add_on_set_parameters_callback(self._on_set)

    def add_pre_set(self, callback: Callable[[list[Parameter]], list[Parameter]]) -> None:
        """A pre-set callback of the node's (it may change the list and add
        to it), run after the conversion to the declared types and those added
        before it, each on what the one before returned."""
        self._pre_set.append(callback)

    def _pre_set_all(self, params: list[Parameter]) -> list[Parameter]:
        for callback in self._pre_set:
            params = callback(params)
        return params

    def _as_declared(self, params: list[Parameter]) -> list[Parameter]:
        """An integer given for a double setting (``ros2 param set v_max 3000``)
        becomes the double it stands for, so every tool reading the parameter
        finds the type its descriptor declares."""
        out = []
        for p in params:
            spec = self.specs.get(p.name)
            if spec is not None and spec.kind is float and type(p.value) is int:
                with contextlib.suppress(SpecError):  # else refused in _on_set, as it was given
                    p = Parameter(p.name, value=spec.check(p.value))
            out.append(p)
        return out

    def _reason_for_override(self, name: str, exc: Exception) -> str:
        override = self.node._parameter_overrides.get(name)
        if override is not None:
            try:
                self.specs[name].check(override.value)
            except SpecError as err:
                return str(err)
        return f"{name}: {str(exc).splitlines()[0]}"

    def values(self) -> dict[str, Any]:
        """Current values, typed; cached until a parameter change is accepted."""
        if self._values is None:
            self._values = {n: s.check(self.node.get_parameter(n).value) for n, s in self.specs.items()}
        return self._values

    def _on_set(self, params: list[Parameter]) -> SetParametersResult:
        merged = {n: self.node.get_parameter(n).value for n in self.specs}
        try:
            for p in params:
                if p.name in self.specs:
                    merged[p.name] = self.specs[p.name].check(p.value)
            self.check({n: self.specs[n].check(v) for n, v in merged.items()})
        except SpecError as exc:
            self.node.get_logger().warning(f"parameter change rejected: {exc}")
            self._keep_declared_types(params)
            return SetParametersResult(successful=False, reason=str(exc))
        self._values = None  # the new values are in place once this returns
        # a start-up rejection is resolved once that parameter is set validly
        names = {p.name for p in params}
        self.rejected = [r for r in self.rejected if r in self.specs and r not in names]
        return SetParametersResult(successful=True)

    def _keep_declared_types(self, params: list[Parameter]) -> None:
        """rclpy gives a dynamically typed parameter's descriptor the type of
        a value it is about to set, before the callbacks may refuse it, and
        keeps it when they do: after ``max_velocity.fork abc`` was refused
        the descriptor said string, ``winder ctl param set`` (which types a
        value by it) sent ``60.0`` as text, and the setting could not be set
        again until the node restarted. The refused ones get their declared
        type back (rclpy's own table: it offers no call for this)."""
        table = getattr(self.node, "_descriptors", None)
        if not isinstance(table, dict):
            return
        for p in params:
            if p.name in self.specs and p.name in table:
                table[p.name].type = descriptor(self.specs[p.name]).type

    def blocked(self) -> str | None:
        """Why the node must not run a job: start-up values it had to refuse."""
        if self.rejected:
            return (
                f"settings rejected at start: {', '.join(self.rejected)}; "
                "set valid values (ros2 param set) to proceed"
            )
        return None
