"""Profile node: S-curve, trapezoid or exponential step timing."""
