"""The managed-node (lifecycle) interface of every winder node.

Each node is an ``rclpy.lifecycle.LifecycleNode``: a cell orchestrator drives
``configure``, ``activate``, ``deactivate``, ``cleanup`` and ``shutdown``
through the standard ``~/change_state`` service (``~/get_state`` and the
others come with it) and brings the nodes up in the order it wants. Started
plainly (``ros2 run``, ``winder run``, the launch file) a node configures and
activates itself at once, as before; with ``-p managed:=true`` it waits,
unconfigured, for the orchestrator.

What each state means here (the node builds its publishers, subscriptions and
services at start, and gates them itself, as the style guide asks):

* unconfigured / inactive: the node takes no run. It says ``inactive`` on
  ``winder/ready`` (so the interp node starts nothing), the interp node
  refuses ``~/start`` with that reason, a job description that arrives is
  refused; status reports go on.
* configure: refused (FAILURE, the reason logged) while the node's settings
  are refused, as a start would be. (A node started plainly with refused
  settings is active but ``blocked``: it takes no run until they are set
  validly, as before.)
* active: as a plainly started node.
* deactivate: refused while the node is in a run (abort it, or wait for its
  end); the run is never cut by a state change.
* shutdown: a run still going is closed as at Ctrl-C (its bag readable,
  marked incomplete).
* a transition the current state does not have (configure an active node,
  a label that is no transition): refused (``success`` false), the reason
  logged, the state unchanged; the node and its run go on.
"""

from __future__ import annotations

from typing import Any

from rcl_interfaces.msg import ParameterDescriptor, ParameterType
from rclpy.event_handler import PublisherEventCallbacks
from rclpy.lifecycle import LifecycleNode, LifecycleState, TransitionCallbackReturn
from rclpy.publisher import Publisher

from winder.contract.params import MANAGED
from winder.ros.dds import LEASE
from winder.ros.rejoin import Restart
from winder.ros.wake import WakeWatch

__all__ = ["LEFT_CELL", "ManagedNode"]

#: the exit status of a node that refused to join its cell: 2, "bad input"
#: in the table of exit codes (docs/RELIABILITY.md) (it was started where it cannot run)
LEFT_CELL = 2


class ManagedNode(LifecycleNode):
    """A winder node with the lifecycle interface (see the module doc).
    Subclasses call :meth:`start_lifecycle` at the end of ``__init__`` and
    implement :meth:`in_run`, :meth:`blocked_reason` and :meth:`lifecycle_changed`."""

    #: the exit status of a node that left its cell (:meth:`leave`); 0 otherwise
    exit_code = 0
    #: False if a shutdown() hook could not let go of an entity (a thread still
    #: waiting on it): the process then ends through the interpreter's teardown
    let_go = True
    #: why the node's process restarts (a hold past the DDS lease: winder.ros.rejoin); "" if it does not
    restarting = ""
    #: the hold (s) it restarts for
    held = 0.0
    #: the restart this process is, when it is one (set by winder.ros.spin before the nodes are made)
    restart: Restart | None = None

    def __init__(self, name: str) -> None:
        super().__init__(name)
        self.active = False
        self.auto = False  # configuring itself at start (not managed)
        self.guard_transitions()
        # a hold (SIGSTOP, a starved host) must not cost the node its place on the others'
        # graphs: it announces itself again when it wakes (winder.ros.wake), and restarts its
        # process after a hold past the DDS lease (winder.ros.rejoin)
        self.wake_watch = WakeWatch(self, self.rejoin)
        described = ParameterDescriptor(description=MANAGED.description, read_only=True)
        self.declare_parameter(MANAGED.name, MANAGED.default, described)

    def create_publisher(
        self, *args: Any, event_callbacks: PublisherEventCallbacks | None = None, **kwargs: Any
    ) -> Publisher:
        """rclpy's ``create_publisher``, but without the writer's default
        QoS-event handlers (unless ``event_callbacks`` asks for some). Each
        is a waitable the executor rebuilds into its wait set at every
        wake-up: a consumer had 26 of them, half its entities, and its
        executor cost about 1 ms of CPU per wake-up. What they did, warn of
        a reader with incompatible QoS or type, the reader's side does too
        (rclpy's and rclcpp's default handlers; winder's subscriptions keep theirs)."""
        if event_callbacks is None:
            event_callbacks = PublisherEventCallbacks(use_default_callbacks=False)
        return super().create_publisher(*args, event_callbacks=event_callbacks, **kwargs)

    def guard_transitions(self) -> None:
        """``~/change_state`` for a transition the current state does not have
        (configure an active node, activate an unconfigured one) replies
        failure with the reason logged. rclpy's own handler lets rcl's
        "Transition is not registered" escape the service callback, and the
        executor ends the node, mid-run included."""
        service = getattr(self, "_service_change_state", None)
        if service is None:
            return
        handler = service.callback

        def guarded(req: Any, resp: Any) -> Any:
            available = self._state_machine.available_transitions
            label = req.transition.label
            valid = any((t[1] == label) if label else (t[0] == req.transition.id) for t in available)
            if not valid:
                asked = repr(label) if label else f"id {req.transition.id}"
                names = ", ".join(sorted({str(t[1]) for t in available})) or "none"
                self.get_logger().warning(
                    f"change_state: transition {asked} refused: not valid from state "
                    f"{self.lifecycle_state()} (valid: {names})"
                )
                resp.success = False
                return resp
            return handler(req, resp)

        service.callback = guarded

    def destroy_node(self) -> None:
        """rclpy's ``destroy_node``, and the lifecycle state machine's handle
        with it. rclpy (Jazzy) leaves the state machine alive, and it holds
        the node's handle: the node, and the process' DDS participant with
        it, stayed on the graph until the interpreter's teardown, and for the
        whole lease (10-20 s) when a process ended without one."""
        super().destroy_node()  # type: ignore[no-untyped-call]
        machine = getattr(self, "_state_machine", None)
        if machine is not None:
            machine.destroy_when_not_in_use()

    def start_lifecycle(self) -> None:
        if self.restart is not None:
            self.get_logger().warning(
                f"restarted after a hold of {self.restart.held:.1f} s, with the parameters it had"
                + (" (active again)" if self.restart.was_active(self) else "")
            )
        managed = self.get_parameter("managed").value is True
        # a restarted node comes back in the state it had; otherwise a managed one waits
        come_up = self.restart.was_active(self) if self.restart is not None else not managed
        if not come_up:
            self.get_logger().info("unconfigured, waiting for configure and activate")
            self.lifecycle_changed()
            return
        # started plainly: active at once; settings refused at start leave the
        # node "blocked" (it takes no run until they are set validly), as before
        self.auto = True
        self.trigger_configure()
        self.trigger_activate()
        self.auto = False

    # -- what a node tells ---------------------------------------------------
    def in_run(self) -> bool:
        """Whether the node is in a run now."""
        return False

    def blocked_reason(self) -> str | None:
        """Why the node cannot be configured (its settings refused), or None."""
        return None

    def lifecycle_changed(self) -> None:
        """The state changed: say so (readiness, status)."""

    def inactive_reason(self) -> str:
        """Why the node takes no run now ("" when active)."""
        if self.active:
            return ""
        return f"{self.get_name()} is not active (lifecycle state: {self.lifecycle_state()})"

    def lifecycle_state(self) -> str:
        return str(self._state_machine.current_state[1])

    # -- transitions -------------------------------------------------------
    def on_configure(self, state: LifecycleState) -> TransitionCallbackReturn:
        why = self.blocked_reason()
        if why and not self.auto:
            self.get_logger().error(f"configure refused: {why}")
            return TransitionCallbackReturn.FAILURE
        return super().on_configure(state)

    def on_activate(self, state: LifecycleState) -> TransitionCallbackReturn:
        self.active = True
        self.lifecycle_changed()
        return super().on_activate(state)

    def on_deactivate(self, state: LifecycleState) -> TransitionCallbackReturn:
        if self.in_run():
            self.get_logger().error("deactivate refused: a run is going on (abort it, or wait for its end)")
            return TransitionCallbackReturn.FAILURE
        self.active = False
        self.lifecycle_changed()
        return super().on_deactivate(state)

    def on_cleanup(self, state: LifecycleState) -> TransitionCallbackReturn:
        return super().on_cleanup(state)

    def on_shutdown(self, state: LifecycleState) -> TransitionCallbackReturn:
        self.active = False
        hook = getattr(self, "shutdown", None)
        if callable(hook):
            hook()
        self.lifecycle_changed()
        return super().on_shutdown(state)

    def rejoin(self, held: float) -> None:
        """The process was held ``held`` s, past the DDS lease: the others
        have dropped its participant, and may never learn its endpoints again.
        End as at Ctrl-C and restart the process (winder.ros.spin does, with
        :meth:`parameters_now`)."""
        if self.restarting:
            return
        self.held = held
        self.restarting = (
            f"{self.get_name()} was held up {held:.1f} s, past the DDS lease ({LEASE:g} s), and restarts "
            "to rejoin the cell"
        )
        self.get_logger().warning(
            f"held up {held:.1f} s (SIGSTOP, a starved host, a debugger), past the DDS lease ({LEASE:g} s): "
            "the other nodes have dropped this one; restarting the process (same pid, the parameters it "
            "has now) to rejoin the cell"
        )
        self.context.try_shutdown()

    def parameters_now(self) -> dict[str, Any]:
        """The node's parameters as they are, for its restart: every value
        set (an empty array has no type rcl can read, and keeps its default)."""
        values: dict[str, Any] = {}
        for name, parameter in self._parameters.items():
            message = parameter.get_parameter_value()
            if message.type == ParameterType.PARAMETER_NOT_SET:
                continue
            value = parameter.value
            if isinstance(value, (list, tuple)) and len(value) == 0:
                continue
            values[name] = value
        return values

    def leave(self, why: str) -> None:
        """Leave the cell at once (another node of this role already runs in
        its namespace: :class:`winder.ros.peers.Solo`): one ERROR line, and
        the process ends with :data:`LEFT_CELL`."""
        self.get_logger().error(why)
        self.exit_code = LEFT_CELL
        self.context.try_shutdown()
