"""Simulated axes: stepper motor model, /clock, MCAP recording."""
