"""The winder cell to ros2_control hardware: position commands, servo fault watch."""
