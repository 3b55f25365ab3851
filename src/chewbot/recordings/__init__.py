"""Recorded jaw motion in: marker recordings (CSV, ArtiSynth probe text, C3D) become robot tasks.

The stages, one module each, in the order the data takes (docs/recordings.md):
:mod:`~chewbot.recordings.formats` (reading), :mod:`~chewbot.recordings.registration` (the TOML file),
:mod:`~chewbot.recordings.prepare` (gaps, low-pass), :mod:`~chewbot.recordings.rigid` (pose per frame, scaling),
:mod:`~chewbot.recordings.fit` (nearest admissible robot pose; its CasADi graphs in
:mod:`~chewbot.recordings.robotfit`), :mod:`~chewbot.recordings.resample` (spline rates, bite force) and
:mod:`~chewbot.recordings.importer` (all of them: :func:`import_motion`). What a recording tracks and its
anatomical registration: :mod:`~chewbot.recordings.anatomy`; the search around it:
:mod:`~chewbot.recordings.register` (rigid bodies) and :mod:`~chewbot.recordings.register_point` (point paths);
re-timing within the limits: :mod:`~chewbot.recordings.retime`. The command line is
:mod:`~chewbot.commands.import_motion`. The names below load on first use, so that the command line starts fast.
"""

from __future__ import annotations

__all__ = ["ImportOptions", "MotionImport", "Recording", "Registration", "RigidFit", "RobotFit", "fit_to_robot",
           "import_motion", "kabsch", "load_registration", "read_recording", "rigid_fit", "scale_motion"]


def __getattr__(name: str):
    if name in ("import_motion", "ImportOptions", "MotionImport"):
        from chewbot.recordings import importer as module
    elif name in ("Recording", "read_recording"):
        from chewbot.recordings import formats as module
    elif name in ("Registration", "load_registration"):
        from chewbot.recordings import registration as module
    elif name in ("RigidFit", "kabsch", "rigid_fit", "scale_motion"):
        from chewbot.recordings import rigid as module
    elif name in ("RobotFit", "fit_to_robot"):
        from chewbot.recordings import fit as module
    else:
        raise AttributeError(f"module 'chewbot.recordings' has no attribute {name!r}")
    return getattr(module, name)
