"""Linear time-invariant systems, stepped exactly: ``x' = A x + B u``,
``y = C x + D u`` with the input ``u`` linear between samples (a
first-order hold), so a sampled input that is itself piecewise linear is
followed without error, and a smooth one to second order in the sample
period.

The step over ``h`` is ``x1 = Phi x0 + G0 u0 + G1 (u1 - u0)`` with ``Phi =
e^{A h}``, ``G0 = int_0^h e^{A s} ds B`` and ``G1 = (1/h) int_0^h e^{A (h -
s)} s ds B``, read off one matrix exponential of the block matrix ``[[A h,
B h, 0], [0, 0, I], [0, 0, 0]]`` (Van Loan). The exponential is Pade(13)
with scaling and squaring (Higham 2005), written here: numpy has none.
"""

from __future__ import annotations

import math

import numpy as np
import numpy.typing as npt

__all__ = ["Discrete", "expm", "periodic_orbit"]

Floats = npt.NDArray[np.float64]

_PADE13 = (
    64764752532480000.0,
    32382376266240000.0,
    7771770303897600.0,
    1187353796428800.0,
    129060195264000.0,
    10559470521600.0,
    670442572800.0,
    33522128640.0,
    1323241920.0,
    40840800.0,
    960960.0,
    16380.0,
    182.0,
    1.0,
)
#: the norm below which Pade(13) is accurate to double precision (Higham 2005, theta_13)
_THETA13 = 5.371920351148152


def expm(a: Floats) -> Floats:
    """The matrix exponential of a square matrix."""
    a = np.asarray(a, dtype=np.float64)
    norm = float(np.abs(a).sum(axis=0).max()) if a.size else 0.0
    squarings = max(0, math.ceil(math.log2(norm / _THETA13))) if norm > _THETA13 else 0
    a = a / 2.0**squarings
    b = _PADE13
    eye = np.eye(a.shape[0])
    a2 = a @ a
    a4 = a2 @ a2
    a6 = a4 @ a2
    u = a @ (a6 @ (b[13] * a6 + b[11] * a4 + b[9] * a2) + b[7] * a6 + b[5] * a4 + b[3] * a2 + b[1] * eye)
    v = a6 @ (b[12] * a6 + b[10] * a4 + b[8] * a2) + b[6] * a6 + b[4] * a4 + b[2] * a2 + b[0] * eye
    out = np.asarray(np.linalg.solve(v - u, v + u), dtype=np.float64)
    for _ in range(squarings):
        out = out @ out
    return out


#: samples :meth:`Discrete.run` steps at a time
BLOCK = 64


class Discrete:
    """A continuous LTI system ``(A, B, C, D)`` of one input, stepped exactly
    over sample period ``h`` with the input linear between samples."""

    def __init__(self, a: Floats, b: Floats, c: Floats, d: Floats, h: float) -> None:
        a, b = np.atleast_2d(np.asarray(a, float)), np.asarray(b, float).reshape(-1, 1)
        self.c, self.d = np.atleast_2d(np.asarray(c, float)), np.asarray(d, float).reshape(-1)
        n = a.shape[0]
        big = np.zeros((n + 2, n + 2))
        big[:n, :n] = a * h
        big[:n, n : n + 1] = b * h
        big[n, n + 1] = 1.0
        e = expm(big)
        self.phi = e[:n, :n]
        self.g0 = e[:n, n]  # int_0^h e^{A s} ds B
        self.g1 = e[:n, n + 1]  # (1/h) int_0^h e^{A (h - s)} s ds B
        self.h = h
        self.n = n
        self._powers: Floats | None = None
        self._toeplitz: Floats | None = None

    def run(self, x0: Floats, u: Floats) -> tuple[Floats, Floats]:
        """The states at every sample of the input ``u`` (``u[0]`` at ``x0``)
        and the outputs there: ``(len(u), n)`` and ``(len(u), outputs)``.
        Stepped :data:`BLOCK` samples at a time: ``x[k] = phi**k x0 + sum
        phi**(k-1-j) w[j]``, ``w[j]`` the input's share of step ``j``."""
        u = np.asarray(u, float)
        xs = np.empty((u.size, self.n))
        x = np.asarray(x0, float).copy()
        if u.size:
            xs[0] = x
        w = u[:-1, None] * (self.g0 - self.g1)[None, :] + u[1:, None] * self.g1[None, :]
        powers, toeplitz = self._blocks()
        for lo in range(0, w.shape[0], BLOCK):
            wb = w[lo : lo + BLOCK]
            m = wb.shape[0]
            size = m * self.n
            forced = (toeplitz[:size, :size] @ wb.reshape(-1)).reshape(m, self.n)
            xs[lo + 1 : lo + 1 + m] = powers[1 : m + 1] @ x + forced
            x = xs[lo + m]
        ys = xs @ self.c.T + u[:, None] * self.d[None, :]
        return xs, ys

    def _blocks(self) -> tuple[Floats, Floats]:
        """``phi**k`` for k = 0..BLOCK, and the block's convolution as one
        matrix: its ``n x n`` block ``[k, j]`` is ``phi**(k-j)`` for ``j <= k``,
        else 0 (made once)."""
        if self._powers is None:
            powers = np.empty((BLOCK + 1, self.n, self.n))
            powers[0] = np.eye(self.n)
            for i in range(1, BLOCK + 1):
                powers[i] = self.phi @ powers[i - 1]
            rows, cols = np.meshgrid(np.arange(BLOCK), np.arange(BLOCK), indexing="ij")
            lag = rows - cols
            blocks = np.where((lag >= 0)[:, :, None, None], powers[np.maximum(lag, 0)], 0.0)
            # as one matrix: row k*n + a, column j*n + b (the block's states and inputs, flattened)
            toeplitz = blocks.transpose(0, 2, 1, 3).reshape(BLOCK * self.n, BLOCK * self.n)
            self._powers, self._toeplitz = powers, toeplitz
        assert self._toeplitz is not None
        return self._powers, self._toeplitz


def periodic_orbit(system: Discrete, u: Floats) -> Floats:
    """The state at the start of the periodic steady state under an input
    repeating ``u`` (its samples over one period, ``u[0]`` again after the
    last): the fixed point of one period's map, solved exactly."""
    u = np.asarray(u, float)
    m = np.eye(system.n)
    r = np.zeros(system.n)
    for k in range(u.size):
        nxt = u[(k + 1) % u.size]
        m = system.phi @ m
        r = system.phi @ r + system.g0 * u[k] + system.g1 * (nxt - u[k])
    return np.asarray(np.linalg.solve(np.eye(system.n) - m, r), dtype=np.float64)
