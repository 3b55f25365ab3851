"""The robot model: the immutable :class:`Model` (:mod:`chewbot.model.model`), its parameter vector and symbolic
mirror (:mod:`chewbot.model.vector`), and the parameter files (:mod:`chewbot.model.params`)."""

from chewbot.model.model import Contact, Friction, HKPGeometry, Limits, MechanismMixin, Model, Uncertainty

__all__ = ["Contact", "Friction", "HKPGeometry", "Limits", "MechanismMixin", "Model", "Uncertainty"]
