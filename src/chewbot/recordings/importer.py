"""A recording in, a robot task and its verdict out: :func:`import_motion` runs every stage in order.

read (:mod:`~chewbot.recordings.formats`) -> markers of the registration -> trim, fill gaps, low-pass
(:mod:`~chewbot.recordings.prepare`) -> tracker to {S}, rigid fit per frame, scaling relative to the first frame
(:mod:`~chewbot.recordings.rigid`) -> fit to the robot (:mod:`~chewbot.recordings.fit`) -> verdict -> spline
resampling and bite force (:mod:`~chewbot.recordings.resample`) -> the task, checked by the kinematics.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

from chewbot.errors import KinematicsError, RecordingError
from chewbot.kinematics.motion import solve_kinematics
from chewbot.model import Model
from chewbot.model.params import load_model
from chewbot.progress import SILENT, Progress
from chewbot.recordings.fit import RobotFit, fit_to_robot, fitted_pose, nearest_admissible
from chewbot.recordings.measures import Measures, measure
from chewbot.recordings.anatomy import Detected, detect
from chewbot.recordings.register import FoundRegistration, fit_registration
from chewbot.recordings.register_point import fit_point_registration
from chewbot.recordings.retime import Retiming, limit_report, retime
from chewbot.recordings.formats import Recording, read_recording
from chewbot.recordings.prepare import fill_gaps, low_pass, spikes, trim
from chewbot.recordings.robotfit import MIN_TRANSMISSION_DEG, hinge_beta
from chewbot.recordings.registration import Registration, collinear, load_registration
from chewbot.recordings.resample import force_at, output_times, read_force_file, spline_motion
from chewbot.recordings.rigid import RigidFit, kabsch, rigid_fit, scale_motion, to_base
from chewbot import units
from chewbot.table import Table
from chewbot.kinematics.task import FULL_COORDS, TARGET_COORDS, Task

# --scale auto: bisection steps on the factor in [0, 1] (resolution 2^-14 = 6e-5).
BISECTIONS = 14
# An incisal-point recording gives no orientation: the fit weighs the rotation from the hinge guess this little
# (per degree, against 1 per mm at the incisor), enough to choose among the poses that put the incisor on the
# point (4 DOF for 3 coordinates), where the incisor can be put there exactly; orientation errors are then not a
# tolerance.
POINT_ORIENTATION_WEIGHT = 0.1
# --scale auto: factors j / SCAN scanned from below first (a power of 2).
SCAN = 16
# --clip: the task starts at home, held HOLD_S, moves to the recording's first pose in RAMP_S (a quintic blend:
# zero rate and acceleration at both ends of the blend), plays the recording, and returns the same way.
RAMP_S = 1.0
HOLD_S = 0.2
# --clip: between two frames the clipped motion's incisor moves at most this many times the largest step of the
# recorded (registered, scaled) motion's incisor between two frames; a larger step is a jump, an error.
JUMP_FACTOR = 2.0


@dataclass(frozen=True)
class ImportOptions:
    """The choices of an import (the command's options; SI where no unit is named).

    ``cutoff_hz`` None: no low-pass; ``rate_hz`` None: the recording's own times; ``scale``: a number, None (the
    registration's) or ``"auto"``; ``angle_scale``: a number or None (the registration's).
    """

    model: str = "target"
    side: str = "left"
    max_gap_s: float = 0.1
    cutoff_hz: float | None = 6.0
    rate_hz: float | None = 1000.0
    scale: float | str | None = None
    angle_scale: float | None = None
    max_position_mm: float = 1.0
    max_orientation_deg: float = 1.0
    max_rigid_mm: float = 1.0
    force_file: str | None = None
    min_transmission_deg: float = MIN_TRANSMISSION_DEG
    fit_registration: bool = False
    keep_spikes: bool = False
    clip: bool = False
    timing: str = "limits"  # "limits": re-timed within the motors' limits where it needs; "recording": the recording's times


@dataclass(frozen=True, eq=False)
class MotionImport:
    """What an import found (arrays frames first).

    ``recording``: the prepared marker paths; ``rigid``: the pose of {M} per frame; ``fit``: the robot's
    nearest admissible poses; ``scale``, ``angle_scale``: the factors applied (``factor``: what ``--scale auto``
    found, else None); ``passed`` (N,): the frames within every tolerance; ``task``: the resampled task (None
    when a frame fails); ``notes``: what the preparation did (trimmed frames, filled gaps, moved samples).
    """

    options: ImportOptions
    model: Model
    registration: Registration
    recording: Recording
    rigid: RigidFit
    fit: RobotFit
    scale: float
    angle_scale: float
    factor: float | None
    passed: np.ndarray
    task: Task | None
    notes: list[str] = field(default_factory=list)
    found: FoundRegistration | None = None
    retiming: Retiming | None = None
    detected: Detected | None = None

    def measures(self) -> Measures:
        """What the robot reproduces of the recording (registered, at scale 1): :func:`measure`."""
        return measure(self.model, self.rigid.p, self.rigid.R, self.fit, self.recording.t, self.tracked_point)

    @property
    def tracked_point(self) -> np.ndarray:
        """The point of {M} (m) whose path a point-path recording gives; the incisal point for a rigid body."""
        return tracked_point(self.model, self.registration.tracked)

    def residuals(self) -> Table:
        """One row per frame: its number in the file, time, the markers' rigid-fit residual (RMS and largest),
        the robot fit's errors, and flags (1/0): an admissible pose found, the recorded motion outside the
        workspace (the unconstrained optimum breaks a constraint), every tolerance met."""
        rec, fit = self.recording, self.fit
        table = Table()
        table.add("frame", rec.first_frame + np.arange(rec.n), "1", "frame number in the recording (from 1)")
        table.add("t", rec.t, "s", "time")
        table.add("rigid_rms", self.rigid.rms_mm, "mm", "RMS distance of the markers from the fitted rigid body")
        table.add("rigid_max", self.rigid.max_mm, "mm", "largest distance of a marker from the fitted rigid body")
        table.add("position_error", fit.position_error_mm, "mm", "distance of the measure point from where it was recorded")
        table.add("orientation_error", fit.orientation_error_deg, "deg", "rotation angle between the fitted and the recorded orientation")
        table.add("admissible", fit.admissible, "1", "1 where an admissible pose was found")
        table.add("leaves_workspace", fit.outside.any(axis=1), "1", "1 where the nearest pose without the constraints is not admissible")
        for j, name in enumerate(fit.constraint_names):
            table.add("outside_" + name.replace(" ", "_"), fit.outside[:, j], "1", f"1 where the recorded pose breaks: {name}")
        table.add("passed", self.passed, "1", "1 where every tolerance is met")
        table.add("clipped", (~self.passed) & (self.task is not None), "1", "1 where --clip put the nearest admissible pose in the task")
        m = self.measures()
        for name, values, unit, what in m.columns():
            table.add(name, values, unit, what)
        limiting = np.zeros(rec.n, dtype=int)
        if self.found is not None:
            limiting[self.found.limiting_frames] = 1
        table.add("limits_share", limiting, "1", "1 where the frame fails just above the share (the frames that limit it)")
        return table

    def summary(self) -> list[str]:
        """The import's measures in lines: the share (with the registration search), what the robot reproduces of
        the recorded rotation and incisal excursion, whether it is in step, what limits it."""
        m, lines = self.measures(), []
        if self.detected is not None:
            lines.append(self.detected.describe())
        if self.found is not None:
            f = self.found
            lines.append(f"share {f.share:.4f} (the largest uniform scale <= 1 of the registered recording at which every frame "
                         f"is reached within --max-residual); weighted residual RMS {f.residual:.3g}; {f.evaluations} "
                         f"evaluations, {f.seconds:.3g} s")
            lines.extend(note for note in f.notes if note.startswith("prior:"))
            lines.append(f.describe())
            if f.share < 1:
                times = self.recording.t[f.limiting_frames]
                shown = ", ".join(f"{t:.3f}" for t in times[:8]) + (" ..." if times.size > 8 else "")
                lines.append(f"limited by {f.limiting} in {f.limiting_frames.size} frame(s) at t = {shown} s")
            if self.factor is not None and self.factor < 1:
                lines.append(f"the task is played at {self.factor:.4f} of the share (scale {self.scale:.4f}): the largest factor "
                             "at which every frame passes and the resampled task stays in the workspace (as --scale auto)")
        elif self.factor is not None:
            lines.append(f"share {self.factor:.4f} (--scale auto)")
        lines.append(m.describe())
        return lines


    def registration_rows(self) -> list[tuple[str, str]]:
        """What the recording tracks and how it was registered, as (what, value) rows: what was detected (or the
        file's ``tracked``), the prior and the registration found with how far it moved from the prior (with
        ``--fit-registration``), and the tracker used (p_S = rotation p_T + origin)."""
        reg, f = self.registration, self.found
        rows = [("what the recording tracks", self.detected.describe() if self.detected is not None
                 else f"tracked = \"{reg.tracked}\" ({'the file' if reg.markers is None or f is not None else 'its [markers]'})")]
        if f is not None:
            rows += [("prior", "; ".join(n for n in f.notes if n.startswith("prior:"))),
                     ("tracker of the prior", _tracker_text(f.prior_rotation, f.prior_origin)),
                     ("registration found", f.describe())]
        rows.append(("tracker used", _tracker_text(reg.rotation, reg.origin)))
        return rows

    def failures(self) -> list[str]:
        """The failing frames, as stretches of consecutive frames with the reasons."""
        return _failure_messages(self)


STEPS = 5  # reading and preparing, registration, rigid fit, fit to the robot, task (the progress callback's calls)


def import_motion(recording: str | Path, registration: str | Path | Registration, options: ImportOptions = ImportOptions(),
                  progress: Progress = SILENT) -> MotionImport:
    """Import a recording as a robot task (see the module docstring). Raises
    :class:`~chewbot.errors.RecordingError` for bad files and :class:`~chewbot.errors.KinematicsError` when the
    resampled task breaks the kinematics; failing frames are reported in the result (``passed``,
    :meth:`MotionImport.failures`), with ``task`` None. ``progress(message)`` is told each of :data:`STEPS` steps."""
    progress("reading and preparing the markers")
    reg = registration if isinstance(registration, Registration) else load_registration(registration)
    model = load_model(options.model)
    notes: list[str] = []
    rec = _prepare(read_recording(recording, reg.units), reg, options, notes)
    if reg.landmarks is not None:
        reg = _placed_by_landmarks(model, reg, rec)
        notes.append(f"the markers placed on the mandible by the landmarks ({', '.join(reg.landmarks)})")
    found, detected = None, None
    if reg.tracked is None:
        detected = detect(model, rec.positions)
        reg = replace(reg, tracked="rigid" if detected.kind == "rigid" else "incisor")
    tracked = reg.point_path
    b = tracked_point(model, reg.tracked)
    point = b if tracked else reg.point
    weights = (reg.position_weight_per_mm, POINT_ORIENTATION_WEIGHT if tracked else reg.orientation_weight_per_deg)
    max_orientation = np.inf if tracked else options.max_orientation_deg
    if tracked and (options.angle_scale not in (None, 1.0) or reg.angle_scale != 1.0):
        raise RecordingError(f"{reg.source}: a point path (tracked = \"{reg.tracked}\") has no rotation to scale: "
                             "its scale applies to the point's displacement, and the hinge guess follows it; leave out "
                             "angle_scale and --angle-scale")
    if options.fit_registration and tracked:
        progress(f"searching the registration of the {reg.tracked} path")
        found = fit_point_registration(model, rec.positions, b, reg.rotation, *weights, options.max_position_mm,
                                       options.min_transmission_deg)
        notes.extend(n for n in found.notes if not n.startswith("prior:"))
        reg = replace(reg, rotation=found.rotation, origin=found.origin, scale=found.share, angle_scale=1.0)
    elif options.fit_registration:
        progress("searching the registration")
        found = fit_registration(model, rec.positions, rec.markers, reg.rotation, reg.markers, reg.point,
                                 weights, (options.max_position_mm, max_orientation), options.min_transmission_deg)
        notes.extend(n for n in found.notes if not n.startswith("prior:"))
        reg = replace(reg, markers=found.markers or None, rotation=found.rotation, origin=found.origin, scale=found.share,
                      angle_scale=found.share, landmarks=None)
    else:
        progress("registration as the file gives it")
    progress("rigid fit")
    points = to_base(rec.positions, reg.rotation, reg.origin)
    if tracked:
        rigid = point_path(model, b, points, rec.markers)
    elif reg.markers is None:
        if collinear(points[0]):
            raise RecordingError(f"{rec.source}: {rec.where(0)}: the markers lie on one line (or nearly) and do not "
                                 "fix the mandible's rotation (rest = \"first\")")
        body = points[0]
    else:
        body = np.array([reg.markers[name] for name in rec.markers])
    if not tracked:
        rigid = rigid_fit(body, points, rec.markers)
    rigid_ok = rigid.max_mm <= options.max_rigid_mm
    scale = reg.scale if options.scale in (None, "auto") else float(options.scale)
    angle_scale = reg.angle_scale if options.angle_scale is None else float(options.angle_scale)

    def scaled(factor: float):
        """The registered motion at ``factor`` times the scales: an incisal point's displacement, with the hinge
        guess of the scaled point; a rigid body's displacement and rotation angle (:func:`scale_motion`)."""
        if tracked:
            moved = point_path(model, b, points, rec.markers, factor * scale)
            return moved.p, moved.R
        return scale_motion(rigid.p, rigid.R, factor * scale, factor * angle_scale)

    def attempt(factor: float):
        p, R = scaled(factor)
        fit = (None if found is None else found.fit_of(p, R)) or fit_to_robot(model, p, R, point, *weights, options.min_transmission_deg)
        within = fit.admissible & (fit.position_error_mm <= options.max_position_mm) & (fit.orientation_error_deg <= max_orientation)
        return fit, within & rigid_ok

    # an incisal point's search ends with frames on the workspace's boundary, where the task's spline between them
    # may leave it: the largest factor of the share at which the task builds, as --scale auto finds it
    auto = options.scale == "auto" or (found is not None and tracked)
    progress("fit to the robot" + (" (searching the scale)" if auto else ""))
    factor = None
    fit, passed = attempt(1.0)
    if auto and not rigid_ok.all():
        notes.append("--scale auto: no factor was searched, frames where a marker moves relative to the others fail at every scale")
    elif auto:
        def builds(fit_f) -> bool:
            try:
                _task(model, rec, reg, fit_f, options, Path(recording), [], point, weights)
                return True
            except (RecordingError, KinematicsError):
                return False

        factor, fit, passed = (1.0, fit, passed) if passed.all() and builds(fit) else _largest_factor(attempt, builds)
        scale, angle_scale = factor * scale, factor * angle_scale
        if found is not None:  # the registration written plays the task as imported
            reg = replace(reg, scale=scale)
    progress("resampling and checking the task")
    task = None
    if passed.all() or (options.clip and fit.admissible.all() and rigid_ok.all()):
        if options.clip and not passed.all():
            p, R = scaled(1.0)
            _check_jumps(model, rec, p, R, fit)
            notes.append(_clip_note(rec, fit, passed))
        task = _task(model, rec, reg, fit, options, Path(recording), notes, point, weights)
    retiming = None
    broken = limit_report(model, task) if task is not None else []
    if broken and options.timing == "limits":
        progress("re-timing within the limits")
        retiming = retime(model, task)
        moved, rows, ok, _ = nearest_admissible(model, retiming.task.q, point, *weights, options.min_transmission_deg)
        # the path between its samples, evaluated at the new times, may cross a boundary it runs along by
        # rounding (nanometres): those samples are put back on it, their rates kept
        task = replace(retiming.task, q=moved) if ok.all() else retiming.task
        slow = retiming.stretch > 1 + 1e-3
        notes.append(f"--timing limits: at the recorded times {'; '.join(broken)}; re-timed from {retiming.original_s:.4g} s to "
                     f"{retiming.duration_s:.4g} s, stretched segments "
                     + (", ".join(f"{a:.3g}-{b:.3g} s x{k:.3g}" for (a, b), k in zip(retiming.segments[slow], retiming.stretch[slow]))
                        or "none") + " (of the task's own time before re-timing)")
        try:
            solve_kinematics(model, task)
        except KinematicsError as exc:
            raise exc.located(f"{recording}: the re-timed task") from None
    elif broken:
        notes.append("--timing recording: " + "; ".join(broken) + " (chewbot run fails these checks; --timing limits, the "
                     "default, re-times the task within them)")
    elif task is not None:
        notes.append("the recorded times hold the crank speed, acceleration and torque limits: the task keeps them")
    return MotionImport(options, model, reg, rec, rigid, fit, scale, angle_scale, factor, passed, task, notes, found, retiming,
                        detected)


def _tracker_text(rotation: np.ndarray, origin: np.ndarray) -> str:
    """A tracker placement in a line: its rotation as a rotation vector (deg) and its origin (mm) in {S}."""
    turn = np.degrees(Rotation.from_matrix(rotation).as_rotvec())
    return (f"rotation vector {np.round(turn, 2).tolist()} deg (angle {np.linalg.norm(turn):.4g} deg), origin "
            f"{np.round(origin / 1e-3, 2).tolist()} mm")


def tracked_point(model: Model, name: str | None) -> np.ndarray:
    """The point of {M} (m) a point path is registered as: the model's landmark of that name (``incisor``,
    ``molar_left``, ``molar_right``, ``condyle_left``, ``condyle_right``); the incisal point otherwise."""
    return {"molar_left": model.molar_left, "molar_right": model.molar_right, "condyle_left": model.hkp.T_L,
            "condyle_right": model.hkp.T_R}.get(name, model.incisor)


def point_path(model: Model, b: np.ndarray, points: np.ndarray, names: tuple[str, ...], scale: float = 1.0) -> RigidFit:
    """A point path: the markers' mean (in {S}) is the point b of {M}, its displacement from the first frame times
    ``scale``; the mandible's orientation per frame is a guess, the rotation about the condylar axis that lowers b
    as far as it dropped below the first frame (:func:`~chewbot.recordings.robotfit.hinge_beta`), weighed little in
    the fit (:data:`POINT_ORIENTATION_WEIGHT`); the pose puts b on the point. The rigid-fit residual is the markers'
    distances from the rigid body they form in the first frame, fitted to every frame (they keep their distances, as
    a face-bow triangle does); that they turn little against the excursion is the detection's rule
    (:func:`~chewbot.recordings.anatomy.detect`), not a residual: a wide-opening analyser recording turning up to 1.4 deg moves
    its points up to 1.65 mm from moving in parallel with their mean. One marker has none; two, or markers on one line, the change of each
    one's distance from their mean (a line's turn keeps those)."""
    mean = points.mean(axis=1)
    offsets = points - mean[:, None]
    if points.shape[1] >= 3 and not collinear(points[0]):
        distances = rigid_fit(points[0], points, names).distances
    else:
        distances = np.abs(np.linalg.norm(offsets, axis=2) - np.linalg.norm(offsets[:1], axis=2))
    mean = mean[0] + scale * (mean - mean[0])
    beta = hinge_beta(model, b, mean[:, 2] - mean[0, 2])
    R = Rotation.from_euler("y", beta[:, None]).as_matrix()
    return RigidFit(mean - R @ b, R, distances, names)


def _placed_by_landmarks(model: Model, reg: Registration, rec: Recording) -> Registration:
    """``rest = "first"`` with landmarks: the mandible's rest pose in the tracker's frame from the landmarks (each
    on the model's point of its name, least squares), and the markers in {M} from it; the tracker's placement
    then puts that rest pose in {S} (not necessarily home)."""
    points = {"incisor": model.incisor, "molar_left": model.molar_left, "molar_right": model.molar_right,
              "condyle_left": model.hkp.T_L, "condyle_right": model.hkp.T_R}
    names = list(reg.landmarks)
    R_B, t_B = (v[0] for v in kabsch(np.array([points[n] for n in names]), np.array([reg.landmarks[n] for n in names])[None]))
    markers = {name: R_B.T @ (rec.positions[0, k] - t_B) for k, name in enumerate(rec.markers)}
    return replace(reg, markers=markers)


def _prepare(rec: Recording, reg: Registration, options: ImportOptions, notes: list[str]) -> Recording:
    """The registration's markers, trimmed, gaps filled and low-passed (:mod:`chewbot.recordings.prepare`)."""
    if reg.markers is not None:
        absent = [name for name in reg.markers if name not in rec.markers]
        if absent:
            raise RecordingError(f"{rec.source}: marker(s) {', '.join(absent)} of the registration {reg.source} are not in the "
                                 f"recording (it has {', '.join(rec.markers)})")
        columns = [rec.markers.index(name) for name in reg.markers]
        rec = replace(rec, markers=tuple(reg.markers), positions=rec.positions[:, columns])
    if options.force_file is not None and rec.force is not None:
        raise RecordingError(f"{rec.source}: the recording has bite force columns and --force-file {options.force_file} "
                             "gives another: give one of them")
    rec, head, tail = trim(rec)
    if head or tail:
        notes.append(f"dropped {head} frame(s) at the start and {tail} at the end where a marker was not seen")
    if not options.keep_spikes:
        body = None if reg.markers is None else np.array([reg.markers[name] for name in rec.markers])
        rec, spiked = spikes(rec, body, options.max_gap_s)
        for i0, i1, why in spiked:
            notes.append(f"tracker spike dropped and filled: {rec.where(i0)} to {rec.where(i1)} ({why})")
    rec, found = fill_gaps(rec, options.max_gap_s)
    if found:
        notes.append(f"filled {len(found)} gap(s) by splines (longest {max(g[3] for g in found):.4g} s, marker {max(found, key=lambda g: g[3])[0]})")
    if options.cutoff_hz is not None:
        rec = low_pass(rec, options.cutoff_hz)
    return rec


def _largest_factor(attempt, builds):
    """The largest factor f in [0, 1] such that every frame passes at f and at every factor of the grid
    j / :data:`SCAN` below it, and the resampled task at f builds (``builds(fit)``: the kinematics accept it).

    The frames' verdict need not be monotone in f near the workspace's edge (a frame's nearest admissible pose
    may cross a tolerance and come back): the scan from below stops at the first grid factor that fails, and the
    bisection (:data:`BISECTIONS` steps in all) runs between it and the grid factor before, on the predicate
    "every frame passes and the task builds" at f and at the interval's lower end, which holds by construction.
    """
    lo, lo_fit, lo_passed = 0.0, *attempt(0.0)
    if not lo_passed.all() or not builds(lo_fit):
        return 0.0, lo_fit, lo_passed
    hi = 1.0
    for j in range(1, SCAN + 1):
        fit, passed = attempt(j / SCAN)
        if not (passed.all() and builds(fit)):
            hi = j / SCAN
            break
        lo, lo_fit, lo_passed = j / SCAN, fit, passed
    else:
        return 1.0, lo_fit, lo_passed
    for _ in range(BISECTIONS - int(np.log2(SCAN))):
        mid = 0.5 * (lo + hi)
        fit, passed = attempt(mid)
        if passed.all() and builds(fit):
            lo, lo_fit, lo_passed = mid, fit, passed
        else:
            hi = mid
    return lo, lo_fit, lo_passed


def _check_jumps(model: Model, rec: Recording, p: np.ndarray, R: np.ndarray, fit: RobotFit) -> None:
    """--clip: the clipped motion's incisor steps between frames within :data:`JUMP_FACTOR` of the recorded one's."""
    p_fit, R_fit = fitted_pose(model, fit.q)
    recorded = np.linalg.norm(np.diff(p + R @ model.incisor, axis=0), axis=1)
    clipped = np.linalg.norm(np.diff(p_fit + R_fit @ model.incisor, axis=0), axis=1)
    bound = JUMP_FACTOR * recorded.max()
    if (clipped > bound).any():
        i = int(np.argmax(clipped))
        raise RecordingError(f"{rec.source}: --clip: the clipped motion jumps {clipped[i] / units.factor('mm'):.3g} mm between {rec.where(i)} "
                             f"and the next frame, more than {JUMP_FACTOR:g} x the recording's largest step "
                             f"({recorded.max() / units.factor('mm'):.3g} mm): the nearest admissible poses switch branches there")


def _clip_note(rec: Recording, fit: RobotFit, passed: np.ndarray) -> str:
    clipped = ~passed
    edges = np.diff(np.r_[0, clipped.astype(int), 0])
    stretches = [(a, b - 1) for a, b in zip(np.flatnonzero(edges == 1), np.flatnonzero(edges == -1))]
    names = [n for n, b in zip(fit.constraint_names, fit.outside[clipped].any(axis=0)) if b]
    shown = "; ".join(f"t = {rec.t[a]:.3f} to {rec.t[b]:.3f} s" for a, b in stretches[:6]) + (" ..." if len(stretches) > 6 else "")
    return (f"--clip: {clipped.sum()} frame(s) in {len(stretches)} stretch(es) clipped to the nearest admissible pose ({shown}), "
            f"by up to {np.nanmax(fit.position_error_mm[clipped]):.3g} mm and {np.nanmax(fit.orientation_error_deg[clipped]):.3g} deg; "
            f"limited by {', '.join(names) if names else 'the residual tolerance'}")


def _ramped(rec: Recording, q: np.ndarray) -> tuple[np.ndarray, np.ndarray, float]:
    """Frames (times from 0, poses) from home at rest to the recording and back (:data:`RAMP_S`, :data:`HOLD_S`),
    and the time at which the recording's first frame is played."""
    dt = float(np.median(np.diff(rec.t)))
    hold, ramp = int(round(HOLD_S / dt)), int(round(RAMP_S / dt))
    u = np.arange(1, ramp) / ramp
    blend = (u**3 * (10 - 15 * u + 6 * u**2))[:, None]
    home = np.zeros(q.shape[1])
    before = np.vstack([np.tile(home, (hold + 1, 1)), home + blend * (q[0] - home)])
    after = np.vstack([q[-1] + blend * (home - q[-1]), np.tile(home, (hold + 1, 1))])
    t = np.r_[rec.t[0] - dt * np.arange(len(before), 0, -1), rec.t, rec.t[-1] + dt * np.arange(1, len(after) + 1)]
    return t - t[0], np.vstack([before, q, after]), len(before) * dt


def _task(model: Model, rec: Recording, reg: Registration, fit: RobotFit, options: ImportOptions, source: Path,
          notes: list[str], point, weights: tuple[float, float]) -> Task:
    """The task: the fitted coordinates resampled (spline rates), samples between frames that a spline carries
    out of the workspace moved back onto it, the bite force, and a check by the kinematics. With --clip it starts
    and ends at rest at home (:func:`_ramped`)."""
    frames_t, frames_q, shift = rec.t, fit.q, 0.0
    if options.clip:
        frames_t, frames_q, start = _ramped(rec, fit.q)
        shift = rec.t[0] - start
        notes.append(f"--clip: the task holds home {HOLD_S:g} s, ramps to the recording's first pose in {RAMP_S:g} s (quintic), "
                     f"plays it from t = {start:.4g} s, and returns the same way")
    t = output_times(frames_t, options.rate_hz)
    q, dq, ddq = spline_motion(frames_t, frames_q, t, at_rest=options.clip)
    moved, rows, ok, worst = nearest_admissible(model, q, point, *weights, options.min_transmission_deg)
    if not ok.all():
        i = int(rows[~ok][0])
        raise RecordingError(f"{rec.source}: between the fitted frames, at t = {t[i]:.6g} s, the spline leaves the "
                             "workspace and no admissible pose is near it; lower --rate or use --rate recording")
    if rows.size:  # the rates then come from a spline through the samples as they are now
        notes.append(f"moved {rows.size} resampled sample(s) back into the workspace, where the spline overshot its "
                     f"boundary between frames (at most {worst})")
        q, dq, ddq = spline_motion(t, moved, t, at_rest=options.clip)
    force = np.zeros((len(t), 3))
    inside = (t + shift >= rec.t[0] - 1e-9) & (t + shift <= rec.t[-1] + 1e-9)  # the recording's own times
    if options.force_file is not None:
        force[inside] = force_at(*read_force_file(options.force_file), t[inside] + shift, options.force_file)
    elif rec.force is not None:
        force[inside] = force_at(rec.t, rec.force, t[inside] + shift, rec.source)
    coords = TARGET_COORDS if model.has_hkp else FULL_COORDS
    task = Task(name=source.stem, t=t, coords=coords, q=q, dq=dq, ddq=ddq, force=force, side=options.side,
                source=str(source), meta={"generator": "import-motion", "registration": reg.source})
    try:  # what chewbot run will check: reachable, in the sockets, not singular
        solve_kinematics(model, task)
    except KinematicsError as exc:
        raise exc.located(f"{source}: the resampled task") from None
    return task


def _failure_messages(result: MotionImport) -> list[str]:
    """Stretches of consecutive frames failing for the same reasons, each with its worst values."""
    o, fit, rec, rigid = result.options, result.fit, result.recording, result.rigid
    worst_marker = np.argmax(rigid.distances, axis=1)
    rigid_bad = rigid.max_mm > o.max_rigid_mm
    kinds = np.column_stack([np.where(rigid_bad, worst_marker, -1), ~fit.admissible,
                             fit.admissible & (fit.position_error_mm > o.max_position_mm),
                             fit.admissible & (fit.orientation_error_deg > o.max_orientation_deg)
                             & (not result.registration.point_path)])
    failing = rigid_bad | kinds[:, 1:].any(axis=1)
    change = np.flatnonzero(np.any(np.diff(kinds, axis=0) != 0, axis=1) | np.diff(failing.astype(int)) != 0) + 1
    out = []
    for lo, hi in zip(np.r_[0, change], np.r_[change, rec.n]):
        if not failing[lo]:
            continue
        span, why = slice(lo, hi), []
        marker, none, position, orientation = kinds[lo]
        if marker >= 0:
            why.append(f"marker {rigid.markers[marker]} moves relative to the others (up to {rigid.max_mm[span].max():.3g} mm "
                       f"> --max-rigid {o.max_rigid_mm:g} mm)")
        if none:
            broken = [n for n, b in zip(fit.constraint_names, fit.outside[span].any(axis=0)) if b]
            why.append("no admissible pose near it" + (f" (the motion leaves the workspace: {', '.join(broken)})" if broken else ""))
        if position:
            why.append(f"position error up to {fit.position_error_mm[span].max():.3g} mm > {o.max_position_mm:g} mm")
        if orientation:
            why.append(f"orientation error up to {fit.orientation_error_deg[span].max():.3g} deg > {o.max_orientation_deg:g} deg")
        where = rec.where(lo) if hi - lo == 1 else f"{rec.where(lo)} to {rec.where(hi - 1)}"
        out.append(f"{where}: {'; '.join(why)}")
    return out
