"""Named layouts of a compiled graph's vector inputs and outputs: one table of blocks builds the graph's arguments and
packs and unpacks them at run time.

A compiled step takes a few long vectors (the inputs every stage of an integrator step shares, the inputs of each
stage) whose entries are blocks of different meaning: the bite point, the friction switch, the model's numbers, a
controller's gains. A :class:`Layout` names those blocks once, in order, with their sizes (as the model's
:data:`~chewbot.model.vector.BLOCKS` lays out ``p``): the graph is built on :meth:`Layout.symbols` and reads its blocks by
name (:meth:`Layout.split`), the caller packs the values it passes by name (:meth:`Layout.pack`) and reads a vector
back by name (:meth:`Layout.unpack`). No code counts offsets; a layout that grows by a block moves every offset
after it, and the graph and the caller move together.

Layouts concatenate (``PLANT + Layout.of(gains=12)``): the closed loop's shared inputs are the plant's and the
controller's. A vector laid out along its rows may have columns (an integrator step's stage inputs: one column per
stage); :meth:`split`, :meth:`pack` and :meth:`unpack` keep them.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import numpy as np


@dataclass(frozen=True)
class Layout:
    """The blocks of a vector, in order: ``blocks`` = ((name, size), ...)."""

    blocks: tuple[tuple[str, int], ...]

    def __post_init__(self):
        names = [name for name, _ in self.blocks]
        if len(set(names)) != len(names):
            raise ValueError(f"a layout names each block once: {names}")
        if any(size < 0 for _, size in self.blocks):
            raise ValueError(f"block sizes are not negative: {self.blocks}")

    @classmethod
    def of(cls, **sizes: int) -> Layout:
        """``Layout.of(B=3, friction=1, p=N_P)``: the blocks in the order given."""
        return cls(tuple((name, int(size)) for name, size in sizes.items()))

    def __add__(self, other: Layout) -> Layout:
        return Layout(self.blocks + other.blocks)

    @property
    def names(self) -> tuple[str, ...]:
        return tuple(name for name, _ in self.blocks)

    @property
    def size(self) -> int:
        return sum(size for _, size in self.blocks)

    def slices(self) -> dict[str, slice]:
        """Each block's rows."""
        return dict(self._slices)

    @cached_property
    def _slices(self) -> dict[str, slice]:
        # computed once per layout: a simulation packs and splits at every integrator step
        out, at = {}, 0
        for name, size in self.blocks:
            out[name] = slice(at, at + size)
            at += size
        return out

    def symbols(self, name: str, sym, columns: int = 1):
        """A symbol of the whole vector (``sym``: ``casadi.SX.sym`` or ``casadi.MX.sym``; ``columns`` columns) and its
        blocks by name: the graph's argument and what the graph reads."""
        x = sym(name, self.size, columns)
        return x, self.split(x)

    def split(self, x) -> dict:
        """The blocks of ``x`` (NumPy array or CasADi expression, laid out along its rows) by name."""
        if isinstance(x, np.ndarray):
            return {name: x[s] for name, s in self._slices.items()}
        return {name: x[s, :] for name, s in self._slices.items()}

    def pack(self, columns: int | None = None, **values) -> np.ndarray:
        """The vector of these blocks (every block given by name; a scalar fills its block, a matrix is laid out column
        by column), or with ``columns``
        the matrix whose rows are laid out so: a block's value is (size, columns), or its size (the same in every
        column), or for a block of one row its row (columns,)."""
        missing, unknown = set(self.names) - set(values), set(values) - set(self.names)
        if missing or unknown:
            raise ValueError(f"pack {', '.join(self.names)}: missing {sorted(missing)}, unknown {sorted(unknown)}")
        shape = (self.size,) if columns is None else (self.size, columns)
        out = np.empty(shape)
        for name, s in self._slices.items():
            value = np.asarray(values[name], float)
            if columns is None:
                value = np.ravel(value, order="F")
            elif value.ndim == 1:  # a block's values for every column, or a one-row block's row
                value = value[:, None] if value.size == s.stop - s.start else value[None, :]
            out[s] = value
        return out

    def unpack(self, x: np.ndarray) -> dict[str, np.ndarray]:
        """The blocks of a packed vector (or matrix: rows laid out so) by name, as arrays (views of ``x``)."""
        x = np.asarray(x)
        if x.shape[0] != self.size:
            raise ValueError(f"a vector of {self.size} rows ({', '.join(self.names)}), not {x.shape[0]}")
        return self.split(x)

