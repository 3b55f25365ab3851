"""The inverse-dynamics formulations, siblings with one signature (their table: :mod:`chewbot.dynamics.registry`).

* :mod:`~chewbot.dynamics.formulations.hessian`: Lagrange-d'Alembert with the rates from Hessians (seed 000, Sect. 5.1);
* :mod:`~chewbot.dynamics.formulations.liang`: the same reduction with the rates by Liang's derivative method (Eq. 61);
* :mod:`~chewbot.dynamics.formulations.dalembert`: the Lagrange-d'Alembert reduction those two share (Eq. 53);
* :mod:`~chewbot.dynamics.formulations.lagrange`: Lagrange's equations of the first kind (seed 000, Sect. 5.2);
* :mod:`~chewbot.dynamics.formulations.core6rss`: the 6RSS core in X_EE with the HKPs projected out;
* :mod:`~chewbot.dynamics.formulations.newton_euler`: Newton-Euler with friction and the optimal distribution (seed 001).

The helpers they share (contact, friction, distribution, the G1 kernel, the indices) stay in :mod:`chewbot.dynamics`.
"""
