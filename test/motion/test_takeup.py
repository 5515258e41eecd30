"""winder.motion.takeup against a numeric flyer: a nozzle circling a
polygon of the layer's contour (its corners and flats sampled here, the
vertices of a sharp core among the points), the wire leaving the contour
where it is tangent, the wire used = free span + arc wound. Its derivatives
by differences are the take-up speed and acceleration; the library's closed
forms must agree. The perimeter is checked against the polygon's edges."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from winder.errors import BadInputError
from winder.motion.takeup import Contour, contour_of_layer, takeup_ratio


def polygon(c: Contour, n: int) -> tuple[np.ndarray, np.ndarray]:
    """Points of the contour counter-clockwise from (a/2, 0), and the arc
    length to each: walked piece by piece (half flat, quarter circle, flat,
    ...), every piece's ends among the points."""
    A, B, r = c.a / 2, c.b / 2, c.r
    ends = [(A - r, B - r), (-(A - r), B - r), (-(A - r), -(B - r)), (A - r, -(B - r))]  # corner centres
    pieces = []  # (function of u in [0, 1] -> points, length)
    start = np.array([A, 0.0])
    for k, (cx, cy) in enumerate(ends):
        a0 = k * math.pi / 2
        p0 = np.array([cx + r * math.cos(a0), cy + r * math.sin(a0)])
        p1 = np.array([cx + r * math.cos(a0 + math.pi / 2), cy + r * math.sin(a0 + math.pi / 2)])
        pieces.append((lambda u, s=start, e=p0: s + u[:, None] * (e - s), float(np.hypot(*(p0 - start)))))
        pieces.append(
            (
                lambda u, cx=cx, cy=cy, a0=a0: np.column_stack(
                    [cx + r * np.cos(a0 + u * math.pi / 2), cy + r * np.sin(a0 + u * math.pi / 2)]
                ),
                r * math.pi / 2,
            )
        )
        start = p1
    pieces.append(
        (
            lambda u, s=start: s + u[:, None] * (np.array([A, 0.0]) - s),
            float(np.hypot(*(np.array([A, 0.0]) - start))),
        )
    )
    total = sum(length for _, length in pieces)
    pts, arcs, at = [], [], 0.0
    for f, length in pieces:
        m = max(256, round(n * length / total))  # a tiny corner arc still well resolved
        u = np.linspace(0.0, 1.0, m, endpoint=False)
        pts.append(f(u))
        arcs.append(at + u * length)
        at += length
    return np.vstack(pts), np.concatenate(arcs)


def wire_used(c: Contour, radius: float, psi: np.ndarray, n: int = 20000) -> np.ndarray:
    """The numeric flyer: for each nozzle angle the wire used (free span +
    arc wound, the arc unwrapped over turns), up to a constant."""
    pts, s = polygon(c, n)
    out = np.empty(psi.size)
    for lo in range(0, psi.size, 256):
        p = psi[lo : lo + 256]
        P = radius * np.column_stack([np.cos(p), np.sin(p)])
        d = pts[None, :, :] - P[:, None, :]
        # the tangent point: the contour point seen most counter-clockwise from the nozzle
        # (the wire wraps counter-clockwise; the whole contour lies to its right seen from P)
        toward = -P
        cross = toward[:, None, 0] * d[:, :, 1] - toward[:, None, 1] * d[:, :, 0]
        ang = np.arctan2(cross, np.einsum("ijk,ik->ij", d, toward))
        k = np.argmax(ang, axis=1)
        rows = np.arange(p.size)
        out[lo : lo + 256] = np.hypot(d[rows, k, 0], d[rows, k, 1]) + s[k]
    jumps = np.concatenate([[0.0], np.cumsum(np.diff(out) < -c.length / 2)])
    return out + jumps * c.length


def nozzle_at(c: Contour, radius: float, theta: float) -> float:
    """The flyer angle at which the wire's line has normal ``theta``: the
    nozzle on that tangent line, ahead of the contour (geometry, not the library)."""
    A, B, r = c.a / 2, c.b / 2, c.r
    h = (A - r) * abs(math.cos(theta)) + (B - r) * abs(math.sin(theta)) + r
    return theta + math.atan2(math.sqrt(radius**2 - h**2), h)


contours = st.builds(
    lambda a, ratio, rfrac: Contour(a, a * ratio, rfrac * min(a, a * ratio) / 2),
    st.floats(0.005, 0.2),
    st.floats(0.1, 12.0),
    st.floats(0.0, 1.0),
)


@settings(max_examples=10, deadline=None)
@given(contours, st.floats(1.05, 20.0))
def test_takeup_speed_is_the_derivative_of_the_wire_used(c: Contour, reach: float) -> None:
    radius = reach * c.h_max
    psi = np.linspace(0.3, 0.3 + 2 * math.pi, 601)
    used = wire_used(c, radius, psi)
    # over every stretch, the wire used = the integral of the library's speed
    fine = np.linspace(psi[0], psi[-1], 100001)
    lever = c.lever(fine, radius)
    integral = np.concatenate([[0.0], np.cumsum((lever[1:] + lever[:-1]) / 2 * np.diff(fine))])
    assert np.max(np.abs((used - used[0]) - np.interp(psi, fine, integral))) < 1e-5 * c.length
    assert math.isclose(integral[-1], c.length, rel_tol=1e-6)  # a turn draws one perimeter
    # the numeric flyer's slowest and fastest draw: at a flat and off a corner's diagonal
    speeds = np.diff(used) / np.diff(psi)
    diagonal = math.atan2(c.b / 2 - c.r, c.a / 2 - c.r)
    eps = 1e-5
    for theta, want in ((0.0, c.a / 2), (math.pi / 2, c.b / 2), (diagonal, c.h_max)):
        at = nozzle_at(c, radius, theta)
        got = wire_used(c, radius, np.array([at - eps, at + eps]), n=200000)
        assert math.isclose((got[1] - got[0]) / (2 * eps), want, rel_tol=1e-3), theta
    assert speeds.min() > c.h_min * (1 - 1e-3) and speeds.max() < c.h_max * (1 + 1e-3)
    assert math.isclose(c.h_max / c.h_min, takeup_ratio(c), rel_tol=1e-15)


@settings(max_examples=10, deadline=None)
@given(contours, st.floats(1.05, 20.0))
def test_takeup_acceleration_is_the_second_derivative_of_the_wire_used(c: Contour, reach: float) -> None:
    radius = reach * c.h_max
    # the numeric flyer's second differences around where the library puts the peak
    theta, peak = c.peak_dlever_where(radius)
    at = nozzle_at(c, radius, theta)
    eps = 2e-4
    psi = at + eps * np.arange(-12, 13)
    u = wire_used(c, radius, psi, n=400000)
    second = np.abs(u[2:] - 2 * u[1:-1] + u[:-2]) / eps**2
    assert math.isclose(second.max(), peak, rel_tol=2e-2, abs_tol=1e-3 * c.h_max)
    # nowhere over a turn do the numeric flyer's differences pass it
    psi = np.linspace(0.0, 2 * math.pi, 1201)
    u = wire_used(c, radius, psi)
    dpsi = psi[1] - psi[0]
    assert (np.abs(u[2:] - 2 * u[1:-1] + u[:-2]) / dpsi**2).max() <= peak * 1.02 + 1e-3 * c.h_max
    # the closed-form dh/dpsi agrees with differences of the library's speed off the flats
    fine = np.linspace(0.0, 2 * math.pi, 4001)
    lever = c.lever(fine, radius)
    slope = np.diff(lever) / np.diff(fine)
    assert np.abs(slope).max() <= peak * (1 + 1e-9) + 1e-12
    exact = c.dlever((fine[1:] + fine[:-1]) / 2, radius)
    close = np.abs(exact - slope) < 2e-2 * (np.abs(exact) + 1e-3 * c.h_max)
    assert close.mean() > 0.98


def test_a_round_core_draws_evenly() -> None:
    c = contour_of_layer("round", 0.001, diameter=0.02)
    assert c.a == c.b == 2 * c.r == 0.022
    assert takeup_ratio(c) == 1.0 and c.peak_dlever(0.5) == 0.0 and c.step_at_flats(0.5) == 0.0
    assert math.isclose(c.length, math.pi * 0.022, rel_tol=1e-15)
    assert np.allclose(c.lever(np.linspace(0, 7, 50), 0.5), 0.011, rtol=0, atol=1e-15)


@settings(max_examples=100, deadline=None)
@given(contours)
def test_perimeter_is_the_polygons(c: Contour) -> None:
    pts, _ = polygon(c, 100000)
    edges = np.hypot(*np.diff(np.vstack([pts, pts[:1]]), axis=0).T).sum()
    assert math.isclose(edges, c.length, rel_tol=1e-6)
    # the layer's contour on a sharp core is today's formula: 2 (w + t) + 2 pi r_l
    layer = contour_of_layer("rect", 0.0007, width=c.a, depth=c.b)
    assert math.isclose(layer.length, 2 * (c.a + c.b) + 2 * math.pi * 0.0007, rel_tol=1e-12)


def test_the_flat_step_is_the_flats_length_far_out() -> None:
    c = Contour(0.04, 0.01, 0.001)
    assert math.isclose(c.step_at_flats(1e6), 0.04 - 2 * 0.001, rel_tol=1e-9)
    assert takeup_ratio(Contour(0.09, 0.01, 0.0)) > 9  # a 9:1 bobbin's corners draw 9 times faster


def test_a_nozzle_inside_the_coil_is_refused() -> None:
    with pytest.raises(BadInputError, match=r"flyer_radius 0\.1 m is invalid"):
        Contour(0.2, 0.1, 0.0).lever(np.zeros(1), 0.1)


@settings(max_examples=200, deadline=None)
@given(contours, st.floats(1.05, 6.0), st.floats(-50.0, 50.0))
def test_the_wire_normals_closed_form_is_the_bisections_root(c: Contour, reach: float, psi0: float) -> None:
    """The root of R cos(alpha) = h(psi - alpha) in [0, pi/2], found here by
    bisection to the last bit (the function falls across the interval)."""
    radius = c.h_max * reach
    psi = psi0 + np.linspace(0.0, 2 * math.pi, 720)
    lo, hi = np.zeros_like(psi), np.full_like(psi, math.pi / 2)
    for _ in range(70):
        mid = (lo + hi) / 2
        ahead = radius * np.cos(mid) > c.h(psi - mid)
        lo, hi = np.where(ahead, mid, lo), np.where(ahead, hi, mid)
    got = c.wire_normal(psi, radius)
    assert np.allclose(got, psi - (lo + hi) / 2, rtol=0, atol=1e-12 * (1 + abs(psi0)))
