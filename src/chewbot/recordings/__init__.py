"""Recorded jaw motion in: marker recordings (CSV, ArtiSynth probe text, C3D) become robot tasks.

The stages, one module each, in the order the data takes (docs/recordings.md):
:mod:`~chewbot.recordings.formats` (reading), :mod:`~chewbot.recordings.registration` (the TOML file),
:mod:`~chewbot.recordings.prepare` (gaps, low-pass), :mod:`~chewbot.recordings.rigid` (pose per frame, scaling),
:mod:`~chewbot.recordings.fit` (nearest admissible robot pose; its CasADi graphs in
:mod:`~chewbot.recordings.robotfit`), :mod:`~chewbot.recordings.resample` (spline rates, bite force) and
:mod:`~chewbot.recordings.importer` (all of them: :func:`import_motion`). The command line is
:mod:`~chewbot.commands.import_motion`. The names below load on first use, so that the command line starts fast.
"""

from __future__ import annotations

import importlib

_EXPORTS = {
    "import_motion": "importer", "ImportOptions": "importer", "MotionImport": "importer",
    "Recording": "formats", "read_recording": "formats",
    "Registration": "registration", "load_registration": "registration",
    "RigidFit": "rigid", "kabsch": "rigid", "rigid_fit": "rigid", "scale_motion": "rigid",
    "RobotFit": "fit", "fit_to_robot": "fit",
}
__all__ = sorted(_EXPORTS)


def __getattr__(name: str):
    if name in _EXPORTS:
        return getattr(importlib.import_module(f"chewbot.recordings.{_EXPORTS[name]}"), name)
    raise AttributeError(f"module 'chewbot.recordings' has no attribute {name!r}")
