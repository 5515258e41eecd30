"""How fast a flyer draws its wire off the supply: the take-up speed over a
turn of a layer, from the layer's contour.

The flyer's nozzle circles the core's centre at radius ``R`` and angle
``psi`` (turning at ``omega``); the wire runs from the nozzle to the point
``T`` where it leaves the coil, tangent to the layer's contour there, and
lies on the contour behind it. The wire used so far is the free span
``|P - T|`` plus the arc wound. Its rate is ``omega * h``, with ``h`` the
distance from the rotation axis to the free wire's line (the moment of the
wire's pull about the axis: a belt's power balance). On a convex contour
with support function ``h(theta)`` (the distance from the centre to the
tangent line of outward normal ``theta``), the wire's line at flyer angle
``psi`` has normal ``theta = psi - alpha`` with ``alpha`` in (0, pi/2) the
one root of ``R cos(alpha) = h(psi - alpha)`` (the nozzle leads the point
it draws from). Differentiating that: ``dh/dpsi = R sin(alpha) h'(theta) /
(R sin(alpha) - h'(theta))``, so the take-up acceleration at constant
``omega`` is ``omega**2`` times that.

A layer's contour on a rectangular ``w x t`` core with corner radius
``r_c`` is a rounded rectangle ``a = w + 2 r_l`` by ``b = t + 2 r_l`` with
corner radius ``r = r_c + r_l`` (``r_l`` the layer's centre above the
core); on a round core of diameter ``D``, a circle of radius ``D/2 + r_l``.
Its support function is ``h(theta) = (a/2 - r)|cos theta| + (b/2 - r)|sin
theta| + r``, so over a turn

* the turn is ``2a + 2b - (8 - 2 pi) r`` long;
* ``h`` is greatest, ``r + sqrt((a/2 - r)**2 + (b/2 - r)**2)``, with the
  wire leaving a corner square to the diagonal: four times a turn, off each
  corner; it is least where a flat lies along the wire, ``min(a, b)/2`` at
  the two longer flats (``max(a, b)/2`` at the other two: four equal minima
  on a square). :func:`takeup_ratio` is greatest over least, 1 on a round
  core;
* ``h'`` jumps by twice a flat's half-length at each flat: the take-up
  acceleration steps there by ``omega**2 x`` the flat's length (for a
  flyer far out; exactly :func:`Contour.step_at_flats`), and it is
  greatest (:meth:`Contour.peak_dlever`) just past a flat, or on a corner
  where the corners are large and the flyer close.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from winder.errors import BadInputError

__all__ = ["Contour", "contour_of_layer", "layer_takeup", "takeup_ratio"]

Floats = npt.NDArray[np.float64]


@dataclass(frozen=True)
class Contour:
    """A rounded rectangle ``a`` by ``b`` (m) with corner radius ``r``
    (``0 <= r <= min(a, b)/2``; a circle when ``a == b == 2r``), centred on
    the flyer's axis."""

    a: float
    b: float
    r: float

    @property
    def length(self) -> float:
        """The perimeter: one turn's wire, ``2a + 2b - (8 - 2 pi) r``."""
        return 2 * self.a + 2 * self.b - (8 - 2 * math.pi) * self.r

    @property
    def h_min(self) -> float:
        return min(self.a, self.b) / 2

    @property
    def h_max(self) -> float:
        return self.r + math.hypot(self.a / 2 - self.r, self.b / 2 - self.r)

    def h(self, theta: Floats) -> Floats:
        """The support function: the distance from the centre to the tangent line of normal ``theta``."""
        ca, cb = self.a / 2 - self.r, self.b / 2 - self.r
        out: Floats = ca * np.abs(np.cos(theta)) + cb * np.abs(np.sin(theta)) + self.r
        return out

    def dh(self, theta: Floats) -> Floats:
        """``dh/dtheta``; at a flat (``theta`` a multiple of pi/2) the value
        just after it (the one-sided limit as ``theta`` grows)."""
        ca, cb = self.a / 2 - self.r, self.b / 2 - self.r
        c, s = np.cos(theta), np.sin(theta)
        # the sign of cos and sin just after theta (at a zero, the sign it takes as theta grows)
        sc = np.where(np.abs(c) < 1e-15, -np.sign(s), np.sign(c))
        ss = np.where(np.abs(s) < 1e-15, np.sign(c), np.sign(s))
        out: Floats = -ca * sc * s + cb * ss * c
        return out

    def wire_normal(self, psi: Floats, radius: float) -> Floats:
        """The normal angle ``theta`` of the free wire's line with the nozzle
        at angle ``psi`` and ``radius`` (> :attr:`h_max`): ``psi - alpha``,
        ``alpha`` the root in [0, pi/2] of ``R cos(alpha) = h(psi - alpha)``.
        Closed form: with the signs ``s1, s2`` of ``cos theta, sin theta``
        (the quadrant the wire's normal lies in) the equation is ``P cos
        alpha + Q sin alpha = r``, ``P = R - (a/2 - r) s1 cos psi - (b/2 - r)
        s2 sin psi``, ``Q = (b/2 - r) s2 cos psi - (a/2 - r) s1 sin psi``, so
        ``alpha = atan2(Q, P) +- acos(r / hypot(P, Q))``. As ``alpha`` lies
        in [0, pi/2], ``theta`` lies in the quadrant of ``psi`` or the one
        before it: of those four candidates the one in [0, pi/2] that solves
        the equation itself is the root (it is unique: the left side falls
        and the right rises)."""
        if not radius > self.h_max:
            raise BadInputError(
                f"flyer_radius {radius:g} m is invalid: the coil's layer reaches {self.h_max:g} m from the "
                "flyer's axis; the nozzle must circle outside it"
            )
        psi = np.asarray(psi, float)
        ca, cb = self.a / 2 - self.r, self.b / 2 - self.r
        c, s = np.cos(psi), np.sin(psi)
        best = np.zeros_like(psi)
        miss = np.full_like(psi, np.inf)
        quadrant = np.floor(psi / (math.pi / 2)).astype(np.int64) % 4  # of psi: theta's, or the one before
        for back in (0, 1):
            quad = (quadrant - back) % 4
            s1 = np.where((quad == 0) | (quad == 3), 1.0, -1.0)  # the signs of cos and sin in it
            s2 = np.where(quad <= 1, 1.0, -1.0)
            p = radius - ca * s1 * c - cb * s2 * s
            q = cb * s2 * c - ca * s1 * s
            phase = np.arctan2(q, p)
            spread = np.arccos(np.clip(self.r / np.hypot(p, q), -1.0, 1.0))
            for alpha in (phase - spread, phase + spread):
                alpha = np.remainder(alpha + math.pi, 2 * math.pi) - math.pi
                alpha = np.where((alpha < 0) & (alpha > -1e-12), 0.0, alpha)
                err = np.abs(radius * np.cos(alpha) - self.h(psi - alpha))
                err = np.where((alpha >= 0) & (alpha <= math.pi / 2), err, np.inf)
                better = err < miss
                best, miss = np.where(better, alpha, best), np.where(better, err, miss)
        out: Floats = psi - best
        return out

    def lever(self, psi: Floats, radius: float) -> Floats:
        """``h`` at flyer angle ``psi``: the take-up speed over ``omega`` (m/rad)."""
        return self.h(self.wire_normal(psi, radius))

    def dlever(self, psi: Floats, radius: float) -> Floats:
        """``dh/dpsi``: the take-up acceleration over ``omega**2`` at constant speed (m/rad**2)."""
        return self.dlever_at(self.wire_normal(psi, radius), radius)

    def dlever_at(self, theta: Floats, radius: float) -> Floats:
        """``dh/dpsi`` where the wire's line has normal ``theta``:
        ``R s h' / (R s - h')`` with ``R s = sqrt(R**2 - h**2)``."""
        rs = np.sqrt(radius**2 - self.h(theta) ** 2)
        d = self.dh(theta)
        out: Floats = rs * d / (rs - d)
        return out

    def peak_dlever(self, radius: float) -> float:
        """The largest ``|dh/dpsi|`` over a turn (0 on a circle): the largest
        of the closed form over the wire's normal on a grid of 2**14 a turn
        (the flats among its points, each taken just after it), refined by
        golden sections around the best point to the last bits."""
        return self.peak_dlever_where(radius)[1]

    def peak_dlever_where(self, radius: float) -> tuple[float, float]:
        """The wire's normal ``theta`` at which ``|dh/dpsi|`` is largest, and that value."""
        grid = np.linspace(0.0, 2 * math.pi, 1 << 14, endpoint=False)
        g = np.abs(self.dlever_at(grid, radius))
        i = int(np.argmax(g))
        step = grid[1] - grid[0]
        lo, hi = grid[i] - step, grid[i] + step
        best_t, best = float(grid[i]), float(g[i])

        def f(t: float) -> float:
            return float(np.abs(self.dlever_at(np.array([t]), radius))[0])

        ratio = (math.sqrt(5) - 1) / 2
        x1, x2 = hi - ratio * (hi - lo), lo + ratio * (hi - lo)
        f1, f2 = f(x1), f(x2)
        for _ in range(80):
            if f1 >= f2:
                hi, x2, f2 = x2, x1, f1
                x1 = hi - ratio * (hi - lo)
                f1 = f(x1)
            else:
                lo, x1, f1 = x1, x2, f2
                x2 = lo + ratio * (hi - lo)
                f2 = f(x2)
        for t, v in ((x1, f1), (x2, f2)):
            if v > best:
                best_t, best = t, v
        return best_t, best

    def step_at_flats(self, radius: float) -> float:
        """The largest jump of ``dh/dpsi`` at a flat (times ``omega**2``: the
        step in the take-up acceleration), ``2 k R**2 s**2 / (R**2 s**2 - k**2)``;
        ``2k``, the flat's length, for a flyer far out."""
        best = 0.0
        for k, h in ((self.b / 2 - self.r, self.a / 2), (self.a / 2 - self.r, self.b / 2)):
            rs = radius * math.sqrt(1 - (h / radius) ** 2)
            best = max(best, 2 * k * rs**2 / (rs**2 - k**2))
        return best


def takeup_ratio(contour: Contour) -> float:
    """The take-up speed's greatest over its least over a turn (1 on a round core)."""
    return contour.h_max / contour.h_min


def contour_of_layer(
    core: str,
    radius: float,
    *,
    diameter: float = 0.0,
    width: float = 0.0,
    depth: float = 0.0,
    corner: float = 0.0,
) -> Contour:
    """The contour of a layer whose centre lies ``radius`` above the core: a
    round core of ``diameter``, or a ``width x depth`` one with ``corner`` radius."""
    if core == "round":
        half = diameter / 2 + radius
        return Contour(2 * half, 2 * half, half)
    return Contour(width + 2 * radius, depth + 2 * radius, corner + radius)


def layer_takeup(contour: Contour | None, flyer_radius: float, omega: float) -> dict[str, float | None]:
    """A layer's take-up with the flyer at ``omega`` rad/s: the wire's least
    and greatest speed over a turn (m/s) and its greatest acceleration
    (m/s**2; all None where the core is not given)."""
    if contour is None:
        return {"takeup_speed_min_m_s": None, "takeup_speed_max_m_s": None, "takeup_accel_max_m_s2": None}
    return {
        "takeup_speed_min_m_s": omega * contour.h_min,
        "takeup_speed_max_m_s": omega * contour.h_max,
        "takeup_accel_max_m_s2": omega**2 * contour.peak_dlever(flyer_radius),
    }
