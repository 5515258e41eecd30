"""Trajectory node: winding job to minimum-deviation step commands."""
