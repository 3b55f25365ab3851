"""What a computation tells the one who waits for it: the :class:`Progress` protocol and :data:`SILENT`, the progress
that shows nothing (every computation's default).

A computation takes ``progress`` and calls it between its stages, ``progress(message, done=None, total=None,
stage=None)``: ``message`` says what it does now (``"inverse dynamics (hessian)"``; the words before a colon name the
stage, those after it its detail: ``"compiling kernels: 2 of 4"``), ``done`` and ``total`` count its units (samples,
evaluations, kernels) where it knows them, and ``stage`` names the points a test may stop at (``dynamics``,
``writing``, ``fit``, ``chunk``, ``simulation``: ``chewbot.commands.common.pause_for_tests``). The command line's
progress display is such a callable; nothing below the command line knows of it.
"""

from __future__ import annotations

from typing import Protocol


class Progress(Protocol):
    """Told each stage of a computation (module docstring); returns nothing, and may raise to stop it (a signal
    arrived)."""

    def __call__(self, message: str, done: int | None = None, total: int | None = None, stage: str | None = None) -> None: ...


class Silent:
    """A :class:`Progress` that shows nothing."""

    def __call__(self, message: str, done: int | None = None, total: int | None = None, stage: str | None = None) -> None:
        return None

    def __repr__(self) -> str:
        return "SILENT"


SILENT: Progress = Silent()
