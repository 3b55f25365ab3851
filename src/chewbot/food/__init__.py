"""Food between the teeth: food laws and their state (:mod:`chewbot.food.law`), where the sample is
(:mod:`chewbot.food.geometry`), and the texture profile analysis (:mod:`chewbot.food.tpa`: the two-bite protocol and
Bourne's measures).

Nothing heavy is imported here: the command line lists the built-in foods without loading NumPy's users."""

# A human-like chewing stroke (docs/bolus.md, "The ideal stroke"): the ideal stroke of :mod:`chewbot.food.bolus`
# closes on the bolus until the particle bed pushes back with this force (N) or the teeth are this close (mm),
# whichever comes first. Here, not in the module, so that the command line's defaults need no NumPy.
CLOSING_FORCE_N = 100.0
MIN_GAP_MM = 0.1
