"""The controllers of a simulation: the table of controllers (:mod:`.table`), one module per control law, their gains
file (:mod:`.gains`) and what the laws share (:mod:`.law`).

Nothing heavy is imported here: the command line reads the table without loading NumPy, CasADi or pydantic."""
