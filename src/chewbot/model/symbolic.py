"""The model's numbers as CasADi expressions: :class:`SymbolicModel`, the symbolic mirror of
:class:`~chewbot.model.Model` whose attributes are slices of the parameter vector ``p`` (:mod:`chewbot.model.vector`),
so a graph builder reads like code written against a model. Every graph of chewbot is built on one: the symbol p of
a mechanism (the graph takes p as its last input and serves every model of the mechanism) or one model's constants
(folded in: a robot's own controller).
"""

from __future__ import annotations

import casadi as ca

from chewbot.model.model import MechanismMixin
from chewbot.model.vector import BLOCKS, N_P, Block, block_slice, vector_digest


class _Group:
    """Attributes of a sub-object (hkp, friction, limits, contact) of :class:`SymbolicModel`."""


class SymbolicModel(MechanismMixin):
    """The model's numbers as CasADi expressions: slices of ``p``, with the attributes and shapes of
    :class:`~chewbot.model.Model` as a graph builder uses them.

    Vectors are columns (``crank_length``: 6x1, ``hkp.T_L``: 3x1); ``G``, ``M`` are lists of six 3x1 columns and
    ``R_C0`` a list of six 3x3 matrices (so ``R_C0[i][:, 2]`` is shaft i); ``hkp.T_R`` mirrors ``hkp.T_L`` in y
    and ``hkp.normal`` is the planes' unit normal. ``p`` is a symbol (``SymbolicModel(mechanism)``: the graph
    takes the parameters as an input) or constants (``SymbolicModel.of(model)``: the model's numbers folded in).
    """

    def __init__(self, mechanism: str, p: ca.SX | None = None):
        if mechanism not in ("target", "6rss"):
            raise ValueError(f"mechanism must be 'target' or '6rss', not {mechanism!r}")
        self.mechanism = mechanism
        # what graphs built on these numbers are cached under: the mechanism for its symbol p, the model's digest for
        # its constants (:meth:`of`), nothing for other expressions
        self.key: object = mechanism if p is None else None
        self.p = ca.SX.sym("p", N_P) if p is None else p
        if self.p.numel() != N_P:
            raise ValueError(f"p has {self.p.numel()} entries, the layout {N_P}")
        for b in BLOCKS:
            owner = self
            *groups, leaf = b.name.split(".")
            for g in groups:
                if not hasattr(owner, g):
                    setattr(owner, g, _Group())
                owner = getattr(owner, g)
            setattr(owner, leaf, self._view(b))
        T_L = self.hkp.T_L
        self.hkp.T_R = ca.vertcat(T_L[0], -T_L[1], T_L[2])
        self.hkp.normal = ca.vertcat(self.hkp.p1, 0, 1) / ca.sqrt(self.hkp.p1**2 + 1)

    @classmethod
    def of(cls, model) -> SymbolicModel:
        """The numbers of ``model`` as constants: graphs built on it have them folded in (no input p)."""
        params = cls(model.mechanism, ca.SX(ca.DM(model.vector())))
        params.key = ("model", model.mechanism, vector_digest(model))
        return params

    def _view(self, b: Block):
        x = self.p[block_slice(b.name)]
        if b.shape in ((), (1,)):
            return x[0]
        if len(b.shape) == 1:
            return x
        if b.shape == (3, 3):
            return ca.reshape(x, 3, 3).T  # row-major in p, column-major in CasADi
        rows = b.shape[0]
        width = b.size // rows
        parts = [x[i * width:(i + 1) * width] for i in range(rows)]
        return [ca.reshape(part, 3, 3).T for part in parts] if len(b.shape) == 3 else parts


def c_name(mechanism: str) -> str:
    """The mechanism's name in C identifiers: ``target``, ``sixrss``."""
    return mechanism.replace("6rss", "sixrss")


def parameter_input(params: SymbolicModel) -> tuple[list, list[str]]:
    """The inputs a graph built on ``params`` adds last: ``([p], ["p"])`` for the symbol p, none for a model's
    constants."""
    return ([params.p], ["p"]) if params.p.is_symbolic() else ([], [])
