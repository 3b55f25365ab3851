"""Closed-loop simulation: plants and controllers behind declared interfaces (:mod:`.interfaces`), the tables of
controllers (:mod:`.controllers.table`) and plant engines (:mod:`.engines`), the options resolved once (:mod:`.options`),
the loop at the control rate (:mod:`.simulator`).

Nothing heavy is imported here: the command line reads the tables without loading NumPy or CasADi."""
