"""A link with a fixed one-way delay, for kernels without ``sch_netem``: two
TUN devices (layer 3, no packet information) and this process between them,
which hands every IP packet read from one to the other ``delay_ms`` later,
in order, in both directions.

    python bench/_delayline.py NAME_A NAME_B DELAY_MS

It creates the devices, prints ``ready`` and then relays until stdin closes
or SIGTERM; the caller moves each device into its network namespace and
gives it an address (bench/_netns.py, ``Hosts(..., delay_ms=...)``). The
file descriptors stay bound to the devices when they change namespace.
A packet waits in memory here for its time, and the devices' transmit
queues are set long (100 000 packets, bench/_netns.py) so that a burst
waits for the relay instead of being dropped: the delay is all this link
adds. The relay is one Python process on one core; the benchmark compares
the cell against raw DDS over the same relay, so its ceiling hits both alike.
"""

from __future__ import annotations

import collections
import contextlib
import fcntl
import os
import select
import signal
import struct
import sys
import time

TUNSETIFF = 0x400454CA
IFF_TUN = 0x0001
IFF_NO_PI = 0x1000


def open_tun(name: str) -> int:
    fd = os.open("/dev/net/tun", os.O_RDWR | os.O_NONBLOCK)
    fcntl.ioctl(fd, TUNSETIFF, struct.pack("16sH", name.encode(), IFF_TUN | IFF_NO_PI))
    return fd


def relay(fa: int, fb: int, delay: float) -> None:
    """Forever: packets from each device to the other, ``delay`` s later."""
    peer = {fa: fb, fb: fa}
    Queue = collections.deque[tuple[float, bytes]]
    queues: dict[int, Queue] = {fa: collections.deque(), fb: collections.deque()}
    watch = [fa, fb, sys.stdin.fileno()]
    while True:
        heads = [q[0][0] for q in queues.values() if q]
        wait = max(0.0, min(heads) - time.monotonic()) if heads else 1.0
        ready, _, _ = select.select(watch, [], [], wait)
        now = time.monotonic()
        for fd in ready:
            if fd not in peer:  # stdin: closed by the parent (or a line): stop
                return
            q = queues[fd]
            for _ in range(256):  # drain what is there, a bounded batch
                try:
                    q.append((now + delay, os.read(fd, 65536)))
                except BlockingIOError:
                    break
                except OSError:  # the device is gone (its namespace deleted): so is the link
                    return
        now = time.monotonic()
        for fd, q in queues.items():
            out = peer[fd]
            while q and q[0][0] <= now:
                with contextlib.suppress(OSError):  # the device is down (its namespace went away)
                    os.write(out, q.popleft()[1])


def main() -> int:
    name_a, name_b, delay_ms = sys.argv[1], sys.argv[2], float(sys.argv[3])
    signal.signal(signal.SIGTERM, lambda *_: sys.exit(0))
    try:
        fa, fb = open_tun(name_a), open_tun(name_b)
    except OSError as e:
        print(f"cannot create TUN devices: {e.strerror}", flush=True)
        return 1
    print("ready", flush=True)
    relay(fa, fb, delay_ms / 1e3)
    return 0


if __name__ == "__main__":
    sys.exit(main())
