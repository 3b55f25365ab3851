"""Food between the teeth: food laws and their state (:mod:`chewbot.food.law`), where the sample is
(:mod:`chewbot.food.geometry`), and the texture profile analysis (:mod:`chewbot.food.tpa`: the two-bite protocol and
Bourne's measures).

Nothing heavy is imported here: the command line lists the built-in foods without loading NumPy's users."""
