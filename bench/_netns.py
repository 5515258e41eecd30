"""Two "hosts" on one machine for the scale-out benchmark and test: network
namespaces joined by a veth link, so that DDS between them goes over UDP as
between machines (no shared memory, no loopback).

    hosts = Hosts("s1")            # namespaces ws1a, ws1b; 10.77.<n>.1 <-> .2
    why = hosts.up()               # "" or the reason the machine does not allow it
    hosts.command("a", [...])      # argv that runs in host a
    hosts.env("a")                 # ROS discovery over the link: static peer = the other host
    hosts.shape(loss=0.01)         # packet loss (eBPF on the link), rate (tbf), delay (netem)
    hosts.down()
    Hosts("s2", delay_ms=5)        # the same over a link that delays every packet 5 ms one way

Needs root (or CAP_NET_ADMIN) and ``ip``; loss needs a kernel with BPF
(a classifier program that drops each packet with probability p is loaded
and pinned here, no compiler needed), ``shape(delay_ms=...)`` needs
``sch_netem``. Where the kernel lacks netem, ``Hosts(tag, delay_ms=d)``
joins the namespaces by two TUN devices and a relay process that delays
every packet by d (bench/_delayline.py) instead of a veth link. Every
method that cannot do its job on this machine returns the reason instead of
raising, so a caller can report it.
"""

from __future__ import annotations

import ctypes
import itertools
import os
import shutil
import struct
import subprocess
import sys
import tempfile
from pathlib import Path

from winder.procs import popen

__all__ = ["Hosts", "available"]

_subnets = itertools.count(1)


def _ip(*args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run(["ip", *args], capture_output=True, text=True, check=False)


def _in(ns: str, *args: str) -> subprocess.CompletedProcess[str]:
    """A command in network namespace ``ns``."""
    return _ip("netns", "exec", ns, *args)


def available() -> str:
    """ "" if this machine lets us create network namespaces and veth links, else why not."""
    if shutil.which("ip") is None:
        return "no `ip` command (iproute2) on this machine"
    probe = f"wprobe{os.getpid()}"
    r = _ip("netns", "add", probe)
    if r.returncode != 0:
        why = r.stderr.strip() or "not permitted"
        return f"cannot create a network namespace: {why} (needs root / CAP_NET_ADMIN)"
    _ip("netns", "del", probe)
    return ""


def _bpf_drop_program(p: float, pin: Path) -> str:
    """Load a tc classifier (eBPF, direct action) that drops a packet with
    probability ``p`` and pin it at ``pin``; "" or why it could not."""
    libc = ctypes.CDLL(None, use_errno=True)
    sys_bpf = 321  # x86-64

    def insn(code: int, dst: int = 0, src: int = 0, off: int = 0, imm: int = 0) -> bytes:
        return struct.pack("<BBhi", code, (src << 4) | dst, off, imm)

    threshold = min(int(p * 2**32), 2**31 - 1)
    prog = b"".join(
        [
            insn(0x85, imm=7),  # r0 = bpf_get_prandom_u32()
            insn(0xB7, dst=1, imm=threshold),  # r1 = p * 2^32
            insn(0x3D, dst=0, src=1, off=2),  # if r0 >= r1: goto pass
            insn(0xB7, dst=0, imm=2),  # r0 = TC_ACT_SHOT (drop)
            insn(0x95),  # exit
            insn(0xB7, dst=0, imm=0),  # pass: r0 = TC_ACT_OK
            insn(0x95),  # exit
        ]
    )
    code = ctypes.create_string_buffer(prog)
    license_ = ctypes.create_string_buffer(b"GPL")
    attr = ctypes.create_string_buffer(128)
    struct.pack_into("<IIQQ", attr, 0, 3, len(prog) // 8, ctypes.addressof(code), ctypes.addressof(license_))
    fd = libc.syscall(sys_bpf, 5, attr, 128)  # BPF_PROG_LOAD, BPF_PROG_TYPE_SCHED_CLS
    if fd < 0:
        return f"cannot load a BPF program: {os.strerror(ctypes.get_errno())}"
    path = ctypes.create_string_buffer(str(pin).encode())
    attr = ctypes.create_string_buffer(128)
    struct.pack_into("<QI", attr, 0, ctypes.addressof(path), fd)
    ok = libc.syscall(sys_bpf, 6, attr, 128)  # BPF_OBJ_PIN
    os.close(fd)
    return "" if ok == 0 else f"cannot pin a BPF program: {os.strerror(ctypes.get_errno())}"


class Hosts:
    """Two network namespaces ``a`` and ``b`` joined by one veth link."""

    def __init__(self, tag: str, delay_ms: float = 0.0) -> None:
        self.names = {"a": f"w{tag}a", "b": f"w{tag}b"}
        self.devs = {"a": f"w{tag}a0", "b": f"w{tag}b0"}
        subnet = 76 + next(_subnets)
        self.addr = {"a": f"10.{subnet}.0.1", "b": f"10.{subnet}.0.2"}
        self.bpffs: Path | None = None
        self.is_up = False
        #: one-way delay of the link (0: a veth link; else TUN devices and a relay)
        self.delay_ms = delay_ms
        self.relay: subprocess.Popen[str] | None = None

    def up(self) -> str:
        why = available()
        if why:
            return why
        self.down()
        a, b = self.names["a"], self.names["b"]
        steps: list[tuple[str, ...]] = [("netns", "add", a), ("netns", "add", b)]
        if self.delay_ms:
            why = self._start_relay()
            if why:
                self.down()
                return why
        else:
            steps.append(("link", "add", self.devs["a"], "type", "veth", "peer", "name", self.devs["b"]))
        for host in "ab":
            ns, dev = self.names[host], self.devs[host]
            if self.delay_ms:  # a point-to-point TUN device
                address = ("addr", "add", self.addr[host], "peer", self.addr[self.other(host)], "dev", dev)
                # a queue long enough that a burst waits for the relay instead of
                # being dropped (500 packets by default): the link delays, it does not lose
                steps.append(("link", "set", dev, "txqueuelen", "100000"))
            else:
                address = ("addr", "add", f"{self.addr[host]}/24", "dev", dev)
            steps += [
                ("link", "set", dev, "netns", ns),
                ("-n", ns, *address),
                ("-n", ns, "link", "set", "lo", "up"),
                ("-n", ns, "link", "set", dev, "up"),
                ("-n", ns, "route", "add", "224.0.0.0/4", "dev", dev),  # DDS multicast discovery, if used
            ]
        for step in steps:
            r = _ip(*step)
            if r.returncode != 0:
                self.down()
                return f"`ip {' '.join(step)}` failed: {r.stderr.strip()}"
        self.is_up = True
        return ""

    def _start_relay(self) -> str:
        """The delay line between the two TUN devices; "" or why not."""
        self.relay = popen(
            [sys.executable, str(Path(__file__).with_name("_delayline.py")), self.devs["a"], self.devs["b"],
             str(self.delay_ms)],
            stdin=subprocess.PIPE,
            stdout=subprocess.PIPE,
            text=True,
        )  # fmt: skip
        assert self.relay.stdout is not None
        said = self.relay.stdout.readline().strip()
        return "" if said == "ready" else f"no delay line: {said or 'the relay did not start'}"

    def other(self, host: str) -> str:
        return "b" if host == "a" else "a"

    def command(self, host: str, argv: list[str]) -> list[str]:
        return ["ip", "netns", "exec", self.names[host], *argv]

    def env(self, host: str, base: dict[str, str] | None = None) -> dict[str, str]:
        """The environment of a ROS process on ``host``: discovery by a static
        peer list (the other host's address), as between machines without multicast."""
        env = dict(os.environ if base is None else base)
        env["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
        env["ROS_STATIC_PEERS"] = self.addr[self.other(host)]
        return env

    def rx_bytes(self, host: str) -> int:
        """Bytes received on ``host``'s end of the link."""
        r = _in(self.names[host], "cat", f"/sys/class/net/{self.devs[host]}/statistics/rx_bytes")
        return int(r.stdout.strip() or 0)

    def shape(self, *, loss: float = 0.0, delay_ms: float = 0.0, rate_mbit: float = 0.0) -> str:
        """Shape both directions of the link (replacing any shaping before):
        ``loss`` (a fraction), ``delay_ms`` one way, ``rate_mbit``; "" or why not."""
        self.unshape()
        for host in "ab":
            ns, dev = self.names[host], self.devs[host]
            qdisc = ["tc", "qdisc", "add", "dev", dev, "root"]
            if delay_ms:
                r = _in(ns, *qdisc, "netem", "delay", f"{delay_ms}ms")
                if r.returncode != 0:
                    return f"no delay: tc netem failed ({r.stderr.strip()}): the kernel lacks sch_netem"
            elif rate_mbit:
                r = _in(ns, *qdisc, "tbf", "rate", f"{rate_mbit}mbit", "burst", "256kb", "latency", "50ms")
                if r.returncode != 0:
                    return f"no rate limit: {r.stderr.strip()}"
            if loss:
                why = self._drop(ns, dev, host, loss)
                if why:
                    return f"no loss: {why}"
        return ""

    def _drop(self, ns: str, dev: str, host: str, loss: float) -> str:
        """The BPF filter that drops packets on ``dev``'s way out; "" or why not."""
        if self.bpffs is None:
            self.bpffs = Path(tempfile.mkdtemp(prefix="winder-bpf-"))
            m = subprocess.run(["mount", "-t", "bpf", "bpf", str(self.bpffs)], capture_output=True, text=True)
            if m.returncode != 0:
                return f"cannot mount bpffs ({m.stderr.strip()})"
        pin = self.bpffs / f"loss_{host}_{int(loss * 1e6)}"
        if not pin.exists():
            why = _bpf_drop_program(loss, pin)
            if why:
                return why
        _in(ns, "tc", "qdisc", "add", "dev", dev, "clsact")
        r = _in(ns, "tc", "filter", "add", "dev", dev, "egress", "bpf", "da", "pinned", str(pin))
        return "" if r.returncode == 0 else f"cannot attach the BPF filter ({r.stderr.strip()})"

    def unshape(self) -> None:
        for host in "ab":
            ns, dev = self.names[host], self.devs[host]
            _in(ns, "tc", "qdisc", "del", "dev", dev, "root")
            _in(ns, "tc", "qdisc", "del", "dev", dev, "clsact")

    def down(self) -> None:
        if self.relay is not None:
            if self.relay.stdin is not None:
                self.relay.stdin.close()  # the relay's signal to stop
            try:
                self.relay.wait(timeout=5)
            except subprocess.TimeoutExpired:
                self.relay.kill()
                self.relay.wait()
            self.relay = None
        for ns in self.names.values():
            _ip("netns", "del", ns)  # takes its end of the link with it
        if self.bpffs is not None:
            subprocess.run(["umount", str(self.bpffs)], capture_output=True, check=False)
            shutil.rmtree(self.bpffs, ignore_errors=True)
            self.bpffs = None
        self.is_up = False
