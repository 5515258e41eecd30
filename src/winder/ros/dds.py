"""The DDS settings every winder process starts with: winder's Fast DDS
profile (``fastdds_profile.xml`` beside this file: discovery timing, the
reliable writers' heartbeat period, UDP as the only transport), unless the
user names a profile of their own or another rmw."""

from __future__ import annotations

import os
from collections.abc import Mapping, MutableMapping
from pathlib import Path

__all__ = [
    "ANNOUNCEMENT",
    "DISCOVERY_SERVER_KEY",
    "LAN_PROFILE",
    "LEASE",
    "PROFILE",
    "PROFILE_KEYS",
    "describe_profile",
    "discovery_server_command",
    "use_profile",
]

PROFILE = Path(__file__).with_name("fastdds_profile.xml")
#: s between two announcements of a participant in winder's profile (its
#: ``leaseAnnouncement``): a newcomer has learnt of every process on its
#: host within about one of them (``winder ctl``'s wait for a missing part)
ANNOUNCEMENT = 0.25
#: s a participant of winder's profile may be silent before the others drop
#: it (its ``leaseDuration``)
LEASE = 10.0
#: for a cell split across hosts over a lossy network: UDP only, datagrams within one MTU
LAN_PROFILE = Path(__file__).with_name("fastdds_lan.xml")
#: the variables Fast DDS reads its XML profiles from (2.x reads the first, 3.x the second)
PROFILE_KEYS = ("FASTRTPS_DEFAULT_PROFILES_FILE", "FASTDDS_DEFAULT_PROFILES_FILE")


def use_profile(environ: MutableMapping[str, str] | None = None) -> str:
    """Point ``environ`` (default: this process' environment, before
    ``rclpy.init``) at winder's profile, unless it names a profile already or
    selects an rmw other than Fast DDS; return the profile in force ("" for none)."""
    env = os.environ if environ is None else environ
    for key in PROFILE_KEYS:
        if env.get(key):
            return env[key]
    rmw = env.get("RMW_IMPLEMENTATION", "")
    if rmw and rmw != "rmw_fastrtps_cpp":
        return ""
    for key in PROFILE_KEYS:
        env[key] = str(PROFILE)
    return str(PROFILE)


def describe_profile(environ: Mapping[str, str] | None = None) -> str:
    """One line on the DDS settings a cell started from ``environ`` (default:
    this process' environment, left unchanged) will run on, for ``winder run``
    to print when part of the cell runs on another host."""
    env = dict(os.environ if environ is None else environ)
    chosen = use_profile(env)
    if not chosen:
        return f"none of winder's ({env.get('RMW_IMPLEMENTATION')})"
    path = Path(chosen)
    if path == PROFILE:
        return (
            "winder's default (UDP only, on one host its loopback; 64 kB datagrams); on a network that "
            "loses packets select the LAN profile on every host (docs/DEPLOYING.md)"
        )
    if path == LAN_PROFILE:
        return "winder's LAN profile (UDP only, datagrams within one MTU)"
    return f"{chosen} (yours)"


#: where ``winder run`` finds a Fast DDS discovery server, when one is used
DISCOVERY_SERVER_KEY = "ROS_DISCOVERY_SERVER"


def discovery_server_command(address: str, port: int, server_id: int) -> tuple[list[str], dict[str, str]]:
    """The argv and environment that run Fast DDS's discovery server from this
    install (``fast-discovery-server`` beside the Python executable: the ROS
    wheels ship it without a library path, so the libraries of the venv and of
    the ``ros_fastrtps`` wheel are named here). Raises FileNotFoundError if the
    install has no server."""
    import sys
    import sysconfig

    binary = Path(sys.executable).parent / "fast-discovery-server"
    if not binary.exists():
        raise FileNotFoundError(str(binary))
    libs = [Path(sys.prefix) / "lib", *Path(sysconfig.get_paths()["purelib"]).glob("ros_fastrtps*.libs")]
    env = dict(os.environ)
    env["LD_LIBRARY_PATH"] = os.pathsep.join(
        [str(p) for p in libs] + ([env["LD_LIBRARY_PATH"]] if env.get("LD_LIBRARY_PATH") else [])
    )
    return [str(binary), "-i", str(server_id), "-l", address, "-p", str(port)], env
