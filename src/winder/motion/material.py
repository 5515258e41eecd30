"""The wire as a material: how hard it may be pulled, how it stretches, what
its resistance becomes.

A wire is its conductor's bare section ``A = pi d_bare**2 / 4`` of a
material with a yield stress ``sigma_y``, a Young's modulus ``E``, a
density ``rho`` and a resistivity at 20 C. Published winding-tension charts
give the largest tension a magnet wire takes as about 10 000 psi
(68.9 MPa) times its bare copper section (AWG 30: 3.49 N, AWG 42: 0.218 N)
and advise winding at 50-80 % of it: the **maximum tension** here is
``sigma_y * A``, and the set tension defaults to half of it.

Below the yield the wire is elastic (strain ``sigma / E``, recovered when
the pull goes). Above it the conductor flows: with linear hardening at the
tangent modulus ``E_t`` it keeps a plastic strain ``(sigma - sigma_y) /
E_t``, and, its volume kept, a stretch ``eps`` raises its resistance by
``(1 + eps)**2 - 1`` (+2 % for 1 %). A flyer whirls the free wire: the wire
running at ``v`` around the flyer carries a stress ``rho v**2 / 2`` of its
own (4 MPa for copper at 30 m/s), which adds to the pull.

Materials (annealed, at 20 C): copper (IEC 60028: 1.7241e-8 ohm m; E 120
GPa; 8 890 kg/m3; the charts' 68.9 MPa; hardening to about 220 MPa over
30 % elongation) and aluminium (EC grade, 61 % IACS: 2.8264e-8 ohm m; E 69
GPa; 2 703 kg/m3; yield about 28 MPa, breaking at about 83 MPa). A job can
set each figure of its own (``wire.yield_stress`` ...). The wire breaks
where the stress reaches the tensile strength (copper about 220 MPa).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

__all__ = ["MATERIALS", "Material", "Wire"]


@dataclass(frozen=True)
class Material:
    """A conductor's figures (SI units)."""

    name: str
    yield_stress: float  #: Pa: where it starts to flow
    modulus: float  #: Pa: Young's modulus
    density: float  #: kg/m3
    resistivity: float  #: ohm m at 20 C
    hardening: float  #: Pa: tangent modulus above the yield
    tensile_strength: float  #: Pa: where it breaks


MATERIALS: dict[str, Material] = {
    "copper": Material("copper", 68.9e6, 120e9, 8890.0, 1.7241e-8, 0.5e9, 220e6),
    "aluminium": Material("aluminium", 28e6, 69e9, 2703.0, 2.8264e-8, 0.2e9, 83e6),
}


@dataclass(frozen=True)
class Wire:
    """A wire of ``material`` with a bare conductor ``bare_diameter`` (m) thick."""

    material: Material
    bare_diameter: float

    @property
    def section(self) -> float:
        """The conductor's section, m2."""
        return math.pi * self.bare_diameter**2 / 4

    @property
    def max_tension(self) -> float:
        """The largest pull before it flows, N: yield stress x bare section."""
        return self.material.yield_stress * self.section

    @property
    def breaking_load(self) -> float:
        """The pull that breaks it, N: tensile strength x bare section."""
        return self.material.tensile_strength * self.section

    @property
    def stiffness_per_length(self) -> float:
        """``E A``, N: a free span of length ``L`` is a spring of ``E A / L`` N/m."""
        return self.material.modulus * self.section

    def whirl_stress(self, speed: float) -> float:
        """The stress of its own the wire carries running at ``speed`` m/s around a flyer, Pa."""
        return self.material.density * speed**2 / 2

    def stress(self, tension: float, speed: float = 0.0) -> float:
        """The conductor's stress under ``tension`` N running at ``speed`` m/s, Pa."""
        return tension / self.section + self.whirl_stress(speed)

    def plastic_strain(self, stress: float) -> float:
        """The stretch it keeps after a stress (0 below the yield)."""
        m = self.material
        return max(stress - m.yield_stress, 0.0) / m.hardening

    def resistance_rise(self, stress: float) -> float:
        """The relative rise of its resistance after a stress: ``(1 + eps)**2 - 1``."""
        eps = self.plastic_strain(stress)
        return (1 + eps) ** 2 - 1
