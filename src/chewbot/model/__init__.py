"""The robot model: the immutable :class:`Model` (:mod:`chewbot.model.model`), its parameter vector and symbolic
mirror (:mod:`chewbot.model.vector`), the parameter files (:mod:`chewbot.model.params`), and the drive train's law
(:mod:`chewbot.model.drive`)."""

from chewbot.model.model import Contact, Drive, Friction, HKPGeometry, Limits, MechanismMixin, Model, Uncertainty

__all__ = ["Contact", "Drive", "Friction", "HKPGeometry", "Limits", "MechanismMixin", "Model", "Uncertainty"]
