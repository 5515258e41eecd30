"""winder's own ROS types (winder_interfaces) made from the core's records.

The core stays ROS-free: it gives the fields (:meth:`ControlEvent.to_fields`,
:func:`winder.contract.stream.description_fields`, :class:`JobReport`) and
reads messages back by their fields (``ControlEvent.from_message``,
``description_text``, ``JobReport.from_message``), which also takes what
rosbags decodes from a bag. Here the messages are made, for the nodes that
publish them.
"""

from __future__ import annotations

import time
from dataclasses import fields

from builtin_interfaces.msg import Time
from diagnostic_msgs.msg import KeyValue
from rclpy.serialization import deserialize_message

from winder.contract.events import ControlEvent
from winder.contract.run import JobReport
from winder.contract.stream import JobPlan, description_fields, description_text, parse_job_description
from winder_interfaces.msg import ControlEvent as ControlEventMsg
from winder_interfaces.msg import JobDescription, JobSegment, JobStop
from winder_interfaces.msg import JobReport as JobReportMsg

__all__ = ["control_event_msg", "job_description_msg", "job_plan", "job_report_msg", "wall_stamp"]


def wall_stamp() -> Time:
    """A builtin_interfaces/Time of the wall clock now."""
    sec, nanosec = divmod(time.time_ns(), 1_000_000_000)
    return Time(sec=sec, nanosec=nanosec)


def job_plan(raw: bytes) -> JobPlan:
    """The checked plan of a ``winder/job`` message's bytes (a
    JobDescription): what the profile node and every consumer take a run
    from. ValueError (one line) for a description that is not its job's;
    anything else for bytes that are no JobDescription."""
    return parse_job_description(description_text(deserialize_message(raw, JobDescription)))


def control_event_msg(event: ControlEvent) -> ControlEventMsg:
    """The winder/control message of an operator event."""
    return ControlEventMsg(**event.to_fields())


def job_description_msg(text: str) -> JobDescription:
    """The winder/job message of a job description's JSON text
    (:func:`winder.contract.stream.describe_job`)."""
    f = description_fields(text)
    return JobDescription(
        **{
            **f,
            "job": [KeyValue(key=k, value=v) for k, v in f["job"]],
            "ramp": [KeyValue(key=k, value=v) for k, v in f["ramp"]],
            "stops": [JobStop(**s) for s in f["stops"]],
            "segments": [JobSegment(**s) for s in f["segments"]],
        }
    )


def job_report_msg(report: JobReport, node: str = "", stamp: Time | None = None) -> JobReportMsg:
    """The typed final report (winder/report, a Wind result) of a consumer's
    report: its own keys in ``extra``; ``node`` the consumer that sent it."""
    values = {f.name: getattr(report, f.name) for f in fields(report) if f.name != "extra"}
    extra = [KeyValue(key=k, value=str(v)) for k, v in report.extra.items()]
    return JobReportMsg(
        **{**values, "state": str(report.state)}, stamp=stamp or wall_stamp(), node=node, extra=extra
    )
