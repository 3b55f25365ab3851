"""Inverse dynamics of both mechanisms: one module per formulation, named in one table
(:mod:`chewbot.dynamics.registry`), with what they share (the contact model, the distribution of the redundant
torques, the energies and the Lagrange-d'Alembert reduction, the seed-001 indices)."""
