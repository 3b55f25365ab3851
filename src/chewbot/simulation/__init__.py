"""Closed-loop simulation: forward dynamics, controllers, the loop at the control rate.

Nothing heavy is imported here: the command line reads :data:`CONTROLLERS` without loading CasADi."""

CONTROLLERS = ("feedforward", "pd", "computed-torque", "impedance", "hybrid")
# The controllers --compare runs side by side (those that need no food).
COMPARED = ("feedforward", "pd", "computed-torque")
