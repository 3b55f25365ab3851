"""Closed-loop simulation: forward dynamics, controllers, the loop at the control rate."""
