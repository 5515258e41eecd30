"""sim_node: timed step commands -> simulated axes, /clock and an MCAP bag.

A :class:`winder.ros.consumer.StepConsumer`: the base does everything the
cell asks of a consumer (handshake, stream checks, receipts, operator events,
programmed stops, stall watch, winder/state, the job status and final
report, the bag); this node holds only the simulation.

Out (besides the consumer's topics): /clock, winder/joint_commands and
winder/joint_states (JointState at ``publish_rate`` Hz of simulated time),
winder/sim_config (String, latched, the motor parameters in force), all of
them recorded.

Time: /clock is the cell's simulated time. It never goes backwards in the
node's life: each job starts at the simulated time the last one ended (a
sample period later); the step times in the messages stay relative to their
job's start, and ``winder/sim_config`` records where the job starts on the
clock (``clock_origin_ns``). Joint states are stamped with /clock. In the bag,
a message's log time is the wall-clock time at which the job started plus the
simulated time since then, so every viewer shows the recording at its real
date and durations in simulated time; ``wall_start_ns`` in sim_config is that
start.

Each axis is a stepper driven through ``winder.axis``: the linear model is
exact between steps, the nonlinear one integrates the sine torque and reports
lost steps. The simulation advances to the time of the last step received and
never beyond, so /clock never runs ahead of the commands; only at rest after
a pause does a real-time run's clock go on with the wall clock (from where it
stands: it never leaps ahead to make up for time the node was held up). A step
that still comes behind the clock is executed at the clock and counted late
(:class:`winder.ros.consumer.StepConsumer`).
"""

from __future__ import annotations

import math
import time
from collections import deque
from typing import Any

import numpy as np
import numpy.typing as npt
from geometry_msgs.msg import WrenchStamped
from rclpy.node import Node
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import JointState

from winder.axis import StepperAxis
from winder.contract.cdr import JointStateEncoder, WrenchEncoder, encode_clocks
from winder.contract.eq7 import layer_of_samples, sample_deviation, step_deviation
from winder.contract.pacing import ns_not_before
from winder.contract.params import MOTOR_FIELDS, PROFILE_SPECS, check_sim
from winder.contract.stream import JobPlan
from winder.contract.topic_table import PACED, SIM, recorded
from winder.contract.topics import (
    TOPIC_CLOCK,
    TOPIC_JOINT_COMMANDS,
    TOPIC_JOINT_STATES,
    TOPIC_STEP_TIMES,
    TOPIC_TENSION,
)
from winder.errors import BadInputError
from winder.motion.axes import AXES, FORK
from winder.ros.consumer import StepConsumer
from winder.ros.diagnostics import ERROR
from winder.ros.engine import Engine, RunPort
from winder.ros.qos import QOS_CLOCK, QOS_STATE
from winder.ros.run_bag import one_line
from winder.ros.spin import spin
from winder.ros.timers import steady_timer
from winder.ros.upstream import ProfileAbort
from winder.tension.check import wire_refusal
from winder.tension.run import WireRun
from winder_sim import PARAMETERS

#: Samples simulated in one go, at most: the node's memory is bounded by this,
#: never by the simulated time a batch of steps covers (at 1 step/s, a chunk of
#: 8192 steps spans 8192 s: 1.6 million samples at 200 Hz).
SAMPLE_BATCH = 1 << 15
#: At rest after a pause in real time, the clock goes on with the wall clock;
#: a node that finds the wall clock more than this many wall seconds beyond
#: its next sample (it fell behind in the motion, or it was held up: a starved
#: host, SIGSTOP) goes on from its clock instead of leaping ahead. A leap would
#: pass the resume the profile node timed from the clock it heard last.
FREE_RUN_LEAP = 0.02
#: s of wall time after which a real-time run waiting for steps says its /clock again
CLOCK_REPEAT = 0.1
#: How far the simulated axes may leave the wire's path (their eq. 7 distance from it, at any
#: sample of a layer), in wire diameters: a turn laid half a diameter off lies on its
#: neighbour's crest, so beyond it the coil has a defect. A lag along the path is no distance
#: from it. The shipped jobs stay within 0.14 of a diameter (ortho_rect, the most: 70 um on
#: 0.5 mm wire); a flyer that stalls leaves the path by millimetres. `winder analyze` judges
#: each turn's place more finely afterwards (winder.analysis.wound: 10 % of a diameter).
PATH_TOLERANCE = 0.5
#: the simulator's own recorded topics
SIM_TOPICS = recorded(PACED, SIM)


def make_axis(values: dict[str, Any], axis: str) -> StepperAxis:
    return StepperAxis(**{k: values[f"{axis}.{k}"] for k in ("Zr", "L", "i_a", "J", "D")})


class AxisSim:
    """One simulated axis: motor tracker + what is needed to convert units."""

    def __init__(self, motor: StepperAxis, model: str, load: float, step_angle: float, joint_step: float):
        self.motor = motor
        self.tracker: Any = motor.linear_tracker() if model == "linear" else motor.nonlinear_tracker(load)
        self.step_angle = step_angle  # motor rad per step
        self.joint_step = joint_step  # joint unit per step
        self.position = 0  # commanded step position after the last step received
        self.last_step_t = -math.inf  # time of this axis' last step (s)
        self.last_dir = 0.0  # its direction
        self.last_dt = math.inf  # and the interval before it (s)
        self.max_error_steps = 0.0

    @property
    def lost_steps(self) -> int:
        """Full steps of the motor lost (the nonlinear model's slips, a tooth pitch each: 2*m
        full steps); the linear model loses none."""
        return int(getattr(self.tracker, "lost_steps", 0))

    @property
    def lost_commanded(self) -> int:
        """The same angle in this axis' commanded steps (of ``motor_step_angle``: a microstep
        of its drive), the unit of every other step count of the run."""
        return round(self.lost_steps * self.motor.full_step / abs(self.step_angle))


class Tally:
    """Sum, count and maximum of distances (the eq. 7 deviation)."""

    def __init__(self) -> None:
        self.total, self.count, self.peak = 0.0, 0, 0.0

    def add(self, dist: npt.NDArray[np.float64]) -> None:
        self.total += float(dist.sum())
        self.count += dist.size
        self.peak = max(self.peak, float(dist.max()))

    @property
    def mean(self) -> float:
        return self.total / max(self.count, 1)


class SimEngine(Engine):
    """The simulated axes: the rows run through each axis' motor model, the
    samples published at ``publish_rate`` Hz of simulated time (see the module doc)."""

    def attach(self, node: Node, run: RunPort) -> None:
        super().attach(node, run)
        self.pub_clock = node.create_publisher(Clock, TOPIC_CLOCK, QOS_CLOCK)
        self.pub_state = node.create_publisher(JointState, TOPIC_JOINT_STATES, QOS_STATE)
        self.pub_cmd = node.create_publisher(JointState, TOPIC_JOINT_COMMANDS, QOS_STATE)
        self.pub_tension = node.create_publisher(WrenchStamped, TOPIC_TENSION, QOS_STATE)
        self.upstream = ProfileAbort(node, run.peers)  # told to abort the run when the wire breaks
        self.clock_ns = -1  # the last /clock published in this node's life (ns)
        self.clock_wall = 0.0  # when it was published (steady s)
        # a real-time run waiting for its steps: /clock said again (see repeat_clock)
        steady_timer(node, CLOCK_REPEAT, self.repeat_clock)
        self.begin_sim(run.values())

    def begin_sim(self, values: dict[str, Any]) -> None:
        """The simulation's state at a run's start."""
        self.axes: list[AxisSim] = []
        self.rate = float(values["publish_rate"])
        self.next_sample = 0  # index of the next sample, t = k / rate
        self.origin_ns = 0  # /clock at the run's start
        self.out: deque[dict[str, Any]] = deque()  # computed samples waiting to be published
        self.rest: npt.NDArray[np.int64] | None = None  # accepted rows beyond the last sample batch
        self.dev_cmd, self.dev_act = Tally(), Tally()  # eq. 7 of the commands and of the axes (m)
        self.wall_pace0 = 0.0  # wall time at which simulated time pace_sim0 was due
        self.pace_sim0 = 0.0
        self.pace_factor = 0.0  # the real_time_factor since wall_pace0
        self.last_seg = -1  # the segment of the last step row simulated (-1: none yet)
        self.t_sim_ns = 0  # simulated time reached, since the run's start (ns)
        self.wire: WireRun | None = None  # the wire, where the job gives its core
        self.wire_stopped = False  # its fault has stopped the run
        self.wire_cut: float | None = None  # the sample time its fault stopped the axes at (s)
        self.refused = ""  # why the run's wire would not hold (winder check's words): the run stops
        self.wire_checked = False

    # -- the consumer's hooks ---------------------------------------------------
    def begin(self, plan: JobPlan, values: dict[str, Any]) -> dict[str, object]:
        self.begin_sim(values)
        # the run starts on the cell's clock one sample after the last one published
        self.origin_ns = 0 if self.clock_ns < 0 else self.clock_ns + round(1e9 / self.rate)
        self.encoder = JointStateEncoder(AXES, plan.job_id)
        self.wire, why = WireRun.of(plan.job, plan.segments, values, self.rate, plan.joint_step[FORK.index])
        for idle in self.wire.idle_faults() if self.wire is not None else []:
            self.node.get_logger().warning(f"run {plan.run_id or plan.job_id}: {idle}")
        if why:  # winder run and winder check refuse such a job; a run started otherwise goes without
            self.node.get_logger().error(
                f"run {plan.run_id or plan.job_id}: the wire is not simulated: {why}"
            )
        joints = list(AXES)
        if self.wire is not None:
            self.upstream.find()  # the run's profile node, before the wire can break
            joints += ["supply", *(["dancer"] if self.wire.tensioner.kind == "dancer" else [])]
            self.wrench = WrenchEncoder(plan.job_id)
        self.state_encoder = JointStateEncoder(joints, plan.job_id)
        for i, axis in enumerate(AXES):
            sim = AxisSim(
                make_axis(values, axis),
                values["model"],
                values[f"{axis}.load_torque"],
                values[f"{axis}.motor_step_angle"],
                plan.joint_step[i],
            )
            sim.position = plan.segments[0].start[i] if plan.segments else 0
            self.axes.append(sim)
        self.check_wire()  # a ramp the run brings is here already
        return {
            "model": values["model"],
            "axes": {axis: {k: values[f"{axis}.{k}"] for k in MOTOR_FIELDS} for axis in AXES},
            "publish_rate": self.rate,
            "settle_time": values["settle_time"],
            "clock_origin_ns": self.origin_ns,
            "real_time": bool(values["real_time"]),
            "real_time_factor": values["real_time_factor"],
            "wire": self.wire_config(),
        }

    def profile_config_heard(self) -> None:
        self.check_wire()

    def check_wire(self) -> None:
        """The run's job against its wire before a step runs, as ``winder
        check`` predicts it (each layer's steady swing at its top speed and
        the coil as wound with its ramps, with the ramp the run is timed
        with: the one it brings, or its profile node's winder/profile_config):
        a job whose wire would not hold stops with ``winder check``'s words
        (winder.tension.check). 0.3 s for jobs/ortho_rect.yaml, 0.7 s on 4
        poles, once a run (``wire_check`` false: none)."""
        plan = self.run.plan
        if plan is None or self.wire is None or self.wire_checked or not self.run.values()["wire_check"]:
            return
        try:
            ramp = plan.ramp if plan.ramp is not None else self.run.run_ramp()
        except (ValueError, TypeError):  # a profile_config that does not parse: nothing to predict with
            return
        if ramp is None:
            return  # this run's ramp is on its way
        self.wire_checked = True
        values = {n: s.default for n, s in PROFILE_SPECS.items()} | ramp
        try:
            self.refused = wire_refusal(plan.job, values, plan.schedule, self.run.values())
        except BadInputError as exc:
            self.node.get_logger().warning(f"the run's wire cannot be predicted: {one_line(exc)}")

    def unrecorded(self) -> frozenset[str]:
        return frozenset() if self.wire is not None else frozenset({"tension"})

    def wire_config(self) -> dict[str, object] | None:
        if self.wire is None:
            return None
        wire, t = self.wire.wire, self.wire.tensioner
        return {
            "material": wire.material.name,
            "max_tension_n": wire.max_tension,
            "breaking_load_n": wire.breaking_load,
            "set_tension_n": t.set_tension,
            "tensioner": t.kind,
            "span_stiffness_n_m": t.stiffness,
        }

    def paces(self) -> bool:
        return bool(self.run.values()["real_time"])

    def batches(self) -> bool:
        return not self.paces()

    def accepts_more(self) -> bool:
        if self.wire_cut is not None or self.refused:
            return False  # the wire's fault stopped the run, or its job is refused (work_wire)
        return self.rest is None and not (self.paces() and self.out and self.ahead())

    def holding(self) -> bool:
        # a wire's fault stopped the axes: they neither go on nor settle (work_wire closes the run)
        return self.rest is not None or self.wire_cut is not None

    def pending(self) -> bool:
        return self.rest is not None or bool(self.out) or self.free_running()

    def free_running(self) -> bool:
        """A real-time run at rest after a pause: its clock goes on."""
        return self.run.at_rest and self.paces()

    def execute(self, rows: npt.NDArray[np.int64]) -> None:
        self.advance(rows)

    def work(self) -> None:
        if self.run.plan is None:
            return
        self.work_wire()
        if self.run.plan is None:  # the wire broke: the run is closed
            return
        real_time = self.paces()
        if self.rest is not None and not (real_time and self.out and self.ahead()):
            rest, self.rest = self.rest, None
            self.advance(rest)
            if self.rest is None and not self.run.chunks_waiting():
                self.run.settle_if_complete()
        if self.run.at_rest and not (self.run.chunks_waiting() or self.rest is not None or self.out):
            # at rest after a pause: the samples go on to the rest, and on with
            # the wall clock in a real-time run (until the resume's steps come)
            rest_ns = self.run.rest_ns()
            assert rest_ns is not None
            rest_s = rest_ns / 1e9
            until = self.free_run_until(rest_s) if real_time else rest_s
            if until * 1e9 > max(self.run.last_step_ns, self.t_sim_ns):
                self.simulate(None, None, until=until)
        self.emit()

    def free_run_until(self, rest_s: float) -> float:
        """How far the clock of a real-time run at rest after a pause goes now
        (s): on with the wall clock, from where it stands. Found more than
        FREE_RUN_LEAP wall seconds beyond its next sample, it does not leap
        there: the pacing goes on from the clock."""
        factor = self.run.values()["real_time_factor"]
        clock = max((self.next_sample - 1) / self.rate, rest_s)  # the last sample computed, or the rest
        allowed = self.paced_until(factor)
        if allowed - (clock + 1.0 / self.rate) > FREE_RUN_LEAP * factor:
            self.wall_pace0, self.pace_sim0, self.pace_factor = time.monotonic(), clock, factor
            return clock
        return max(allowed, rest_s)

    def earliest_step_ns(self) -> int | None:
        """The last sample computed (ns, rounded up): the trackers take no step before it."""
        if self.next_sample == 0:
            return None
        return ns_not_before((self.next_sample - 1) / self.rate)  # as the trackers have it

    def settle(self, until_ns: int) -> None:
        self.simulate(None, None, until=until_ns / 1e9 + self.run.values()["settle_time"])

    def flush(self) -> None:
        while self.out:
            block = self.out.popleft()
            self.publish_samples(block, block["k"].size)

    def resume_pacing(self) -> None:
        if self.wall_pace0:  # the job waited for ~/resume: pacing goes on from here, it does not catch up
            self.wall_pace0, self.pace_sim0 = time.monotonic(), self.t_sim_ns / 1e9

    def checked(self, seg: int, rows: npt.NDArray[np.int64]) -> None:
        """Eq. 7 of the commanded steps, as ``winder analyze`` computes it (winder.contract.eq7)."""
        assert self.run.plan is not None
        if self.run.plan.segments[seg].kind.winds:
            self.dev_cmd.add(step_deviation(self.run.plan, seg, rows[:, 2:]))

    def details(self) -> dict[str, object]:
        wire = self.wire.details() if self.wire is not None else {}
        worst = max(range(len(self.axes)), key=lambda i: self.axes[i].max_error_steps, default=None)
        return {
            **wire,
            "lost_steps": sum(a.lost_steps for a in self.axes),
            "lost_commanded_steps": sum(a.lost_commanded for a in self.axes),
            "max_tracking_error_steps": f"{max((a.max_error_steps for a in self.axes), default=0.0):.4f}",
            "max_tracking_error_axis": AXES[worst] if worst is not None else "",
            "mean_deviation_command_m": f"{self.dev_cmd.mean:.6e}",
            "max_deviation_command_m": f"{self.dev_cmd.peak:.6e}",
            "mean_deviation_actual_m": f"{self.dev_act.mean:.6e}",
            "max_deviation_actual_m": f"{self.dev_act.peak:.6e}",
            "path_tolerance_m": f"{self.path_tolerance():.6e}",
        }

    def path_tolerance(self) -> float:
        """How far the axes may leave the wire's path (m): PATH_TOLERANCE of the job's wire."""
        plan = self.run.plan
        return PATH_TOLERANCE * plan.job.wire_diameter if plan is not None else math.nan

    def simulated(self) -> bool:
        return True

    def faults(self) -> str:
        """What the simulated axes did that they were not commanded to, in words with their
        units (the final report's ``faults``): steps lost, the wire's path left by more than
        :data:`PATH_TOLERANCE` of its diameter; then the wire's own faults."""
        said: list[str] = []
        lost = [(name, a) for name, a in zip(AXES, self.axes, strict=True) if a.lost_steps]
        if lost:
            each = ", ".join(f"{name} {a.lost_steps}" for name, a in lost)
            commanded = sum(a.lost_commanded for _, a in lost)
            said.append(
                f"{sum(a.lost_steps for _, a in lost)} full steps lost ({each}; {commanded} commanded steps)"
            )
        bound = self.path_tolerance()
        if self.dev_act.count and self.dev_act.peak > bound:
            said.append(
                f"the axes left the wire's path: up to {self.dev_act.peak * 1e6:.1f} um from it, over the "
                f"{bound * 1e6:.1f} um allowed ({PATH_TOLERANCE:g} x the wire's diameter)"
            )
        if self.refused:
            said.append(f"refused: {self.refused}")
        elif self.wire is not None:
            said += self.wire.faults()
        return "; ".join(said)

    def work_wire(self) -> None:
        """A fault of the wire (a break, a slip) stops the run: said, the
        profile node asked to abort, the run closed."""
        if self.wire is None or self.wire_stopped or self.run.plan is None:
            return
        fault = self.wire.fault
        if fault is None and not self.refused:
            return
        self.wire_stopped = True
        self.flush()  # the samples up to the fault and after it go out and into the bag first
        plan = self.run.plan
        if plan is None:
            return
        values: dict[str, object] = {"job_id": plan.job_id, "run_id": plan.run_id}
        if fault is not None:
            text = f"{self.wire.fault_text()}; the run stops"
            values.update(fault.values())
        else:
            text = f"job {plan.job_id} refused: {self.refused}"
            values["fault"] = "refused"
        self.node.get_logger().error(text)
        self.run.publish_status("wire", ERROR, text, values)
        self.upstream.ask(TOPIC_STEP_TIMES)
        self.run.finish(complete=False)

    # -- the simulation -----------------------------------------------------------
    def advance(self, rows: npt.NDArray[np.int64]) -> None:
        """Simulate accepted rows (possibly of several chunks and segments) in
        batches of at most SAMPLE_BATCH samples: as fast as possible, each
        batch is published before the next; in real time, the rows beyond the
        first batch wait in ``self.rest`` until its samples are out."""
        t_s = rows[:, 0] / 1e9
        n, lo = rows.shape[0], 0
        while lo < n:
            end = (self.next_sample + SAMPLE_BATCH - 1) / self.rate  # the batch's last sample
            hi = int(np.searchsorted(t_s, end, side="right"))  # a step at a sample goes before it
            if hi == lo:
                self.simulate(None, None, until=end)  # no step within the batch: samples only
            else:
                self.simulate(rows[lo:hi], t_s[lo:hi], until=float(t_s[hi - 1]) if hi == n else end)
            if self.wire_cut is not None:  # the wire's fault stopped the axes there: no row after it runs
                self.run.executed(int(np.searchsorted(t_s[lo:hi], self.wire_cut, side="right")))
                return
            self.run.executed(hi - lo)
            lo = hi
            if lo < n:
                if self.paces():
                    self.rest = rows[lo:]
                    return
                self.emit()

    def simulate(
        self, rows: npt.NDArray[np.int64] | None, t_s: npt.NDArray[np.float64] | None, until: float
    ) -> None:
        """Advance every axis to ``until`` with the steps in ``rows``; queue the samples."""
        k1 = math.floor(until * self.rate + 1e-9) + 1
        ks = np.arange(self.next_sample, max(k1, self.next_sample), dtype=np.int64)
        samples = ks / self.rate
        self.next_sample = max(k1, self.next_sample)
        cmd_pos = np.empty((samples.size, len(AXES)))
        cmd_vel = np.zeros((samples.size, len(AXES)))
        act_pos = np.empty((samples.size, len(AXES)))
        act_vel = np.empty((samples.size, len(AXES)))
        # the command's segment at each sample: that of the last row at or before it (eq. 7)
        seg_of_sample = np.full(samples.size, self.last_seg, np.int64)
        j = np.empty(0, np.int64)
        if rows is not None and t_s is not None:
            j = np.searchsorted(t_s, samples, side="right") - 1  # last row at or before each sample
            seg_of_sample = np.where(j >= 0, rows[np.maximum(j, 0), 1], self.last_seg)
            self.last_seg = int(rows[-1, 1])
        for i, ax in enumerate(self.axes):
            if rows is not None and t_s is not None:
                p = rows[:, 2 + i]
                d = np.empty(p.size, np.int64)
                d[0] = p[0] - ax.position
                np.subtract(p[1:], p[:-1], out=d[1:])
                if np.count_nonzero(d) == d.size:  # the major axis: every row is its step
                    ev_t, dm = t_s, d
                else:
                    moved = d != 0
                    ev_t, dm = t_s[moved], d[moved]
                ev_a = dm * ax.step_angle
                # commanded step position at each sample (a step at a sample time counts)
                cmd_steps = np.where(j >= 0, p[np.maximum(j, 0)], ax.position)
                # commanded velocity: one step per interval since the axis' step
                # before; once the axis pauses it decays as 1 / (time since the step)
                v_steps = self.command_velocity(ax, ev_t, dm, samples)
                ax.position = int(p[-1])
            else:
                ev_t, ev_a = np.empty(0), np.empty(0)
                cmd_steps = np.full(samples.size, ax.position)
                v_steps = ax.last_dir / np.maximum(ax.last_dt, samples - ax.last_step_t)
            theta, omega = ax.tracker.advance(ev_t, ev_a, samples)
            actual_steps = theta / ax.step_angle
            cmd_pos[:, i] = cmd_steps * ax.joint_step
            cmd_vel[:, i] = v_steps * ax.joint_step
            act_pos[:, i] = actual_steps * ax.joint_step
            act_vel[:, i] = omega / ax.step_angle * ax.joint_step
        if samples.size:
            block = {"k": ks, "cmd_pos": cmd_pos, "cmd_vel": cmd_vel, "act_pos": act_pos, "act_vel": act_vel}
            keep = samples.size
            if self.wire is not None:
                fork = FORK.index
                wire, keep = self.wire.samples(samples, act_pos[:, fork], act_vel[:, fork], seg_of_sample)
                block.update(wire)
                if self.wire.fault is not None and self.wire_cut is None:
                    # the wire's fault (seen in this block) stops the axes there: nothing after counts
                    self.wire_cut = self.wire.fault.seen_s
                    block = {key: value[:keep] for key, value in block.items()}
            for i, ax in enumerate(self.axes):
                error = np.abs(cmd_pos[:keep, i] - act_pos[:keep, i]) / abs(ax.joint_step)
                ax.max_error_steps = max(ax.max_error_steps, float(error.max(initial=0.0)))
            self.deviation_of_axes(seg_of_sample[:keep], act_pos[:keep])
            self.out.append(block)

    @staticmethod
    def command_velocity(
        ax: AxisSim,
        ev_t: npt.NDArray[np.float64],
        dm: npt.NDArray[np.int64],
        samples: npt.NDArray[np.float64],
    ) -> npt.NDArray[np.float64]:
        """Commanded velocity (steps/s) at the samples from the axis' steps
        ``ev_t`` (s) of signs ``dm``: the direction of its last step over the
        longer of that step's interval and the time since it; updates the
        axis' last step, direction and interval."""
        m = ev_t.size
        if m == 0:
            return ax.last_dir / np.maximum(ax.last_dt, samples - ax.last_step_t)
        jj = np.searchsorted(ev_t, samples, side="right")  # this call's steps at or before each sample
        last = np.maximum(jj - 1, 0)
        before = np.where(jj >= 2, ev_t[np.maximum(jj - 2, 0)], ax.last_step_t)
        t_at = np.where(jj >= 1, ev_t[last], ax.last_step_t)
        dirs = np.where(jj >= 1, np.sign(dm[last]), ax.last_dir)
        with np.errstate(invalid="ignore"):  # -inf - -inf before an axis' first step, not chosen
            dts = np.where(jj >= 1, t_at - before, ax.last_dt)
        v: npt.NDArray[np.float64] = dirs / np.maximum(dts, samples - t_at)
        prev = float(ev_t[-2]) if m >= 2 else ax.last_step_t
        ax.last_step_t, ax.last_dir = float(ev_t[-1]), float(np.sign(dm[-1]))
        ax.last_dt = ax.last_step_t - prev
        return v

    def deviation_of_axes(self, segs: npt.NDArray[np.int64], act_pos: npt.NDArray[np.float64]) -> None:
        """Eq. 7 of the samples, as ``winder analyze`` computes it (winder.contract.eq7)."""
        assert self.run.plan is not None
        js = self.run.plan.joint_step
        x, y = act_pos[:, 0] / js[0], act_pos[:, 1] / js[1]
        layer = layer_of_samples(self.run.plan, segs, y)
        if np.any(layer >= 0):
            dist = sample_deviation(self.run.plan, layer, x, y)
            self.dev_act.add(dist[layer >= 0])

    # -- out -------------------------------------------------------------
    def emit(self) -> None:
        """Publish queued samples: all of them, or as far as the wall clock allows."""
        limit = self.paced_until(self.run.values()["real_time_factor"]) if self.paces() else math.inf
        while self.out:
            block = self.out[0]
            ks = block["k"]
            n = int(np.searchsorted(ks / self.rate, limit, side="right")) if math.isfinite(limit) else ks.size
            if n:
                self.publish_samples(block, n)
            if n < ks.size:
                for key in block:
                    block[key] = block[key][n:]
                return
            self.out.popleft()

    def ahead(self) -> bool:
        """In real time: the samples computed reach beyond what the wall clock
        allows now, so the next chunk can wait (memory stays bounded); short
        chunks (the profile node's look-ahead at a high real_time_factor) are
        simulated until they catch up with the clock."""
        if self.wall_pace0 == 0.0:
            return True
        return (self.next_sample - 1) / self.rate > self.paced_until(self.run.values()["real_time_factor"])

    def publish_samples(self, block: dict[str, Any], n: int) -> None:
        """The first ``n`` samples of a block: /clock first, then commands and
        states, each sample's three messages before the next sample's."""
        t_ns = np.rint(block["k"][:n] * (1e9 / self.rate)).astype(np.int64)
        stamps = t_ns + self.origin_ns  # on the cell's clock
        clocks = encode_clocks(stamps)
        cmds = self.encoder.encode(stamps, block["cmd_pos"][:n], block["cmd_vel"][:n])
        if "tension" in block:
            pos = np.hstack([block["act_pos"][:n], block["wire_pos"][:n]])
            vel = np.hstack([block["act_vel"][:n], block["wire_vel"][:n]])
            acts = self.state_encoder.encode(stamps, pos, vel)
            wrenches = self.wrench.encode(stamps, block["tension"][:n])
        else:
            acts = self.encoder.encode(stamps, block["act_pos"][:n], block["act_vel"][:n])
            wrenches = []
        if n:
            self.clock_ns = int(stamps[n - 1])
            self.clock_wall = time.monotonic()
        record = self.run.record
        for r in range(n):
            t = int(t_ns[r])
            self.t_sim_ns = t
            self.pub_clock.publish(clocks[r])
            self.pub_cmd.publish(cmds[r])
            self.pub_state.publish(acts[r])
            record("clock", t, clocks[r], exact=True)
            record("joint_commands", t, cmds[r], exact=True)
            record("joint_states", t, acts[r], exact=True)
            if wrenches:
                self.pub_tension.publish(wrenches[r])
                record("tension", t, wrenches[r], exact=True)
        if n:
            self.run.reached(int(t_ns[n - 1]))

    def repeat_clock(self) -> None:
        """In a real-time run the clock stands still while the node waits for
        the next steps, and the profile node sends them only as the clock
        comes within its look-ahead: a reader of /clock that matched the
        node's writer after its last sample (discovery under load; /clock is
        volatile) would wait for a clock that waits for it. So the last
        /clock goes out again every CLOCK_REPEAT s while nothing else does
        (not recorded: the bag has it once)."""
        if self.run.plan is None or not self.paces() or self.clock_ns < 0:
            return
        if time.monotonic() - self.clock_wall >= CLOCK_REPEAT:
            self.pub_clock.publish(encode_clocks(np.array([self.clock_ns], np.int64))[0])
            self.clock_wall = time.monotonic()

    def paced_until(self, factor: float) -> float:
        """Simulated time (s) the wall clock allows in real-time mode. A new
        real_time_factor changes the rate from now on: the time already
        elapsed keeps the factor it elapsed at (the clock never jumps)."""
        now = time.monotonic()
        if self.wall_pace0 == 0.0:
            self.wall_pace0, self.pace_sim0, self.pace_factor = now, 0.0, factor
        elif factor != self.pace_factor:
            self.pace_sim0 += (now - self.wall_pace0) * self.pace_factor
            self.wall_pace0, self.pace_factor = now, factor
        return self.pace_sim0 + (now - self.wall_pace0) * factor


class SimNode(StepConsumer):
    """The sim node: the cell's consumer with simulated axes."""

    def __init__(self) -> None:
        super().__init__(
            "sim_node", PARAMETERS, check_sim, SimEngine(), hardware_id="winder_sim", topics=SIM_TOPICS
        )


def main(args: list[str] | None = None) -> None:
    spin(SimNode, args)
