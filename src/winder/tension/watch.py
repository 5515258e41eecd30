"""Watching the wire as a winding controller's sensors see it: a load cell's
tension, the flyer's speed, the supply's pay-out counter and the tensioner's
own position. ROS-free: the sim node feeds it its simulated sensors, a
hardware consumer the real ones.

Two faults stop a run:

* **a wire break**: the tension stays below :data:`BREAK_SHARE` of the set
  tension for :data:`BREAK_TIME` while the flyer turns (faster than
  :data:`TURNING` rad/s): a wire that holds has its tension whatever the
  tensioner's swing (the alarm band's bottom is far above), and a flyer at
  rest may hold none. The fault is placed at the first sample of the low
  run: where the wire went.
* **a slip or a count mismatch**: the wire paid out (the supply's counter)
  against what the turns took less what the free span and the tensioner
  hold (the take-up from the flyer's angle through the layer's contour,
  :mod:`winder.motion.takeup`, and the tensioner's state) differ by more
  than ``tension.slip_tolerance`` (m). Placed at the first sample past it.

Each is reported once, as a :class:`WireFault` naming the coil, the layer
and the turn (the coil's turn, counted from 1 over its layers, as the
programmed stops count them).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

__all__ = ["BREAK_SHARE", "BREAK_TIME", "TURNING", "Place", "WireFault", "WireWatch"]

Floats = npt.NDArray[np.float64]

#: a tension below this share of the set tension, with the flyer turning, is no wire
BREAK_SHARE = 0.1
#: s the tension must stay so low before it counts as a break (a load cell's noise, a bounce)
BREAK_TIME = 0.01
#: rad/s above which the flyer counts as turning (drawing wire)
TURNING = 0.5


@dataclass(frozen=True)
class WireFault:
    """A fault of the wire: ``kind`` ``break`` or ``slip``, when (s into the
    run) and where, and the sentence that says it."""

    kind: str
    t_s: float
    coil: int
    layer: int
    turn: int
    text: str
    seen_s: float  #: when the watch knew it (a break: BREAK_TIME later), s into the run

    def values(self) -> dict[str, object]:
        """The keys of the ``wire`` ERROR status (and of ``winder analyze``'s ``break``)."""
        return {
            "fault": self.kind,
            "coil": self.coil,
            "layer": self.layer,
            "turn": self.turn,
            "t_s": f"{self.t_s:.6f}",
        }


#: where sample ``k`` of a block is: (coil, layer, turn), from 1 (0, 0, 0: off the coil)
Place = Callable[[int], tuple[int, int, int]]


class WireWatch:
    """The watch of one run (see the module doc), fed block by block."""

    def __init__(self, set_tension: float, slip_tolerance: float) -> None:
        self.set_tension = set_tension
        self.slip_tolerance = slip_tolerance
        self.low_since: tuple[float, tuple[int, int, int], float] | None = None  # t, place, speed
        self.fault: WireFault | None = None

    def feed(
        self,
        t: Floats,
        tension: Floats,
        flyer_speed: Floats,
        place: Place,
        paid: Floats | None = None,
        expected: Floats | None = None,
    ) -> WireFault | None:
        """The next samples: times (s), tension (N), the flyer's speed
        (rad/s), where each is, and (both or neither) the wire paid out and
        what should have been (m). The fault they show, once; None else."""
        if self.fault is not None or not t.size:
            return None
        fault = self._break(t, tension, flyer_speed, place)
        if paid is not None and expected is not None:
            slip = self._slip(t, paid, expected, place)
            if slip is not None and (fault is None or slip.t_s < fault.t_s):
                fault = slip
        self.fault = fault
        return fault

    def _break(self, t: Floats, tension: Floats, speed: Floats, place: Place) -> WireFault | None:
        low = (tension < BREAK_SHARE * self.set_tension) & (np.abs(speed) > TURNING)
        if not low.any():
            self.low_since = None
            return None
        # the low runs: where each starts, carried over from the last block
        for k in range(int(np.argmax(low)) if self.low_since is None else 0, t.size):
            if not low[k]:
                self.low_since = None
                continue
            if self.low_since is None:
                self.low_since = (float(t[k]), place(k), float(abs(speed[k])))
            t0, (coil, layer, turn), omega = self.low_since
            if t[k] - t0 >= BREAK_TIME:
                return WireFault(
                    "break",
                    t0,
                    coil,
                    layer,
                    turn,
                    f"wire break at coil {coil} layer {layer} turn {turn} ({t0:.3f} s into the run): "
                    f"the tension fell below {BREAK_SHARE * self.set_tension:.3g} N (set "
                    f"{self.set_tension:.4g} N) with the flyer at {omega:.3g} rad/s",
                    float(t[k]),
                )
        return None

    def _slip(self, t: Floats, paid: Floats, expected: Floats, place: Place) -> WireFault | None:
        off = paid - expected
        past = np.flatnonzero(np.abs(off) > self.slip_tolerance)
        if not past.size:
            return None
        k = int(past[0])
        coil, layer, turn = place(k)
        more = "more" if off[k] > 0 else "less"
        return WireFault(
            "slip",
            float(t[k]),
            coil,
            layer,
            turn,
            f"wire slip at coil {coil} layer {layer} turn {turn} ({t[k]:.3f} s into the run): the supply "
            f"paid out {abs(off[k]) * 1e3:.1f} mm {more} than the turns took ({paid[k]:.4g} m against "
            f"{expected[k]:.4g} m; tension.slip_tolerance {self.slip_tolerance * 1e3:g} mm)",
            float(t[k]),
        )
