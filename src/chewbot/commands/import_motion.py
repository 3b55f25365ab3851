"""``chewbot import-motion``: a jaw-tracking recording in, a robot task and its residuals out.

The command's options and files; the work is :func:`chewbot.recordings.importer.import_motion`, the report page
:func:`chewbot.report.recording_figures.recording_report_html`. The files are written together through
:func:`chewbot.files.atomic_files` (all or none): the CSVs with a sidecar, the others beginning with chewbot's
marker line, which names the command; an existing file is replaced only with ``--force`` and only if chewbot wrote it.
"""

from __future__ import annotations

import shlex
from pathlib import Path

import typer

from chewbot.kinematics.options import Side

DEFAULT_MAX_RESIDUAL = (1.0, 1.0)  # mm, deg


def _number_or(word: str, what: str):
    """A typer callback: a positive number, or ``word`` (returned as None)."""

    def parse(value: str | None):
        if value is None or value == word:
            return value
        try:
            number = float(value)
        except ValueError:
            raise typer.BadParameter(f"{value!r} is neither a number nor '{word}'") from None
        if not number > 0:
            raise typer.BadParameter(f"{what} must be positive, not {value}")
        return value

    return parse


def import_motion(
    recording: Path = typer.Argument(..., help="The recording: CSV (.csv: t, NAME_x, NAME_y, NAME_z, ...), C3D (.c3d) or ArtiSynth numeric probe text (any other suffix)."),
    registration: Path = typer.Option(..., "--registration", help="TOML file: units, the markers in {M} (or rest = \"first\"), what the recording tracks (tracked = \"rigid\", \"incisor\" or another landmark; detected from the data when absent), the tracker's placement, scales and fit weights (docs/recordings.md)."),
    out: Path = typer.Option(..., "--out", help="Task CSV to write (chewbot run --task reads it); beside it the per-frame residuals (*.residuals.csv), the incisor paths (*.incisor.svg) and the report of what the robot reproduces (*.report.html: errors in mm and deg, share, r)."),
    model: str = typer.Option("target", "--model", help="The robot: a built-in model (target, 6rss, ...) or a TOML parameter file."),
    side: Side = typer.Option(Side.left, "--side", help="Molar where the bite force acts: recorded in the task's header; run the task with the same --side."),
    max_gap: float = typer.Option(0.1, "--max-gap", min=0.0, help="Longest gap (s) of a marker that is filled by a spline; longer ones are an error."),
    cutoff: str = typer.Option("6", "--cutoff", callback=_number_or("none", "--cutoff"), help="Zero-phase low-pass cutoff (Hz) of the marker paths, or 'none'."),
    rate: str = typer.Option("1000", "--rate", callback=_number_or("recording", "--rate"), help="Sampling rate (Hz) of the task, or 'recording' for the recording's own times."),
    scale: str | None = typer.Option(None, "--scale", callback=_number_or("auto", "--scale"), show_default=False, help="Factor on the displacement of O_M relative to the first frame (default: the registration's), or 'auto': the largest factor <= 1 on both scales at which every frame and the resampled task pass, at it and at every factor j/16 below it."),
    angle_scale: float | None = typer.Option(None, "--angle-scale", min=0.0, show_default=False, help="Factor on the rotation angle relative to the first frame (default: the registration's)."),
    max_residual: tuple[float, float] = typer.Option(DEFAULT_MAX_RESIDUAL, "--max-residual", help="MM DEG: a frame fails when the fitted pose is farther than MM (at the measure point) or DEG (rotation angle) from the recorded one."),
    max_rigid: float = typer.Option(1.0, "--max-rigid", min=0.0, help="A frame fails when a marker is farther than this (mm) from the rigid body fitted to all of them."),
    min_transmission: float = typer.Option(10.0, "--min-transmission", min=0.0, max=90.0, help="Smallest transmission angle (deg) of every chain in an admissible pose: a margin from the chains' dead points (the run's near-singular threshold by default)."),
    force_file: Path | None = typer.Option(None, "--force-file", help="Bite force CSV: t, Fx, Fy, Fz (on the mandible, in {S}; units in brackets), interpolated to the task's times."),
    fit_registration: bool = typer.Option(False, "--fit-registration", help="Find the registration (tracker placement, markers' placement for rest = \"first\") from anatomy: the opening axis on the condylar axis, the condyles' glide on the robot's condylar path (a point path: the face-bow triangle or its opening direction), intercuspal contact at home; refined within 10 deg and 5 mm of that only where frames are beyond --max-residual, for the largest share of the recording the robot reproduces; writes it beside the task, *.registration.toml, and uses the share as the scale."),
    timing: str = typer.Option("limits", "--timing", help="'limits' (default): where the recorded times break the model's crank speed (rad/s), acceleration (rad/s^2) or torque (N*m) limits, the task is re-timed as fast as they allow and never faster than recorded (time-optimal, TOPP-RA), starting and ending at rest, and the time stretch per 0.5 s segment is printed; otherwise it keeps the recorded times. 'recording': the recorded times always, and which limit fails where is printed. Example: --timing recording."),
    clip: bool = typer.Option(False, "--clip", help="Write the task even where frames are beyond --max-residual: those are clipped to the nearest admissible pose (named in the residuals), and the task starts and ends at rest at home (0.2 s hold, 1 s quintic ramp)."),
    keep_spikes: bool = typer.Option(False, "--keep-spikes", help="Keep the frames of tracker spikes (by default frames whose rigid-body error or speed jump is an outlier are dropped and filled like gaps, and listed)."),
    force: bool = typer.Option(False, "--force", help="Replace the output files if they exist."),
) -> None:
    """Turn a jaw-tracking recording (markers on the mandible) into a task for the robot.

    Prepares the marker paths (gaps filled, zero-phase low-pass), fits the mandible's pose per frame, scales the
    motion, finds the robot's nearest admissible pose in each frame, resamples it and writes the task and, beside
    it, the per-frame residuals; prints their maxima. Frames beyond --max-residual or --max-rigid, or with no
    admissible pose near them, are named and the command exits with 3 (the residuals are written, the task is not).
    With --fit-registration the registration is searched first (docs/recordings.md): the share of the recording
    the robot reproduces, what limits it and the registration found are printed and written.

    Examples:

      chewbot import-motion examples/markers/chewing.c3d --registration examples/markers/subject.toml --out task.csv && chewbot run --task task.csv

      chewbot import-motion examples/markers/chewing.csv --registration examples/markers/subject.toml --out task6.csv --model 6rss --scale auto

      chewbot import-motion examples/recordings/chewing.csv --registration examples/recordings/chewing.toml --fit-registration --out task.csv
    """
    from chewbot.commands.common import EXIT_BAD_INPUT, EXIT_UNREACHABLE, console, errors_reported, fail, progress, stdout
    from chewbot.errors import ChewbotError, FitError
    from chewbot.files import WRITTEN_FILE, atomic_files, check_output, marker_line
    from chewbot.recordings.importer import STEPS, ImportOptions, import_motion as run_import
    from chewbot.task.csvio import task_table

    residuals = out.with_name(out.stem + ".residuals.csv")
    side = side.value
    found_toml = out.with_name(out.stem + ".registration.toml")
    figure = out.with_name(out.stem + ".incisor.svg")
    page = out.with_name(out.stem + ".report.html")
    if timing not in ("recording", "limits"):
        fail(ChewbotError(f"--timing must be recording or limits, not {timing!r}"), EXIT_BAD_INPUT)
    if fit_registration and (scale is not None or angle_scale is not None):
        fail(ChewbotError("--fit-registration finds the scale (the share): leave out --scale and --angle-scale"), EXIT_BAD_INPUT)
    options = ImportOptions(model=model, side=side, max_gap_s=max_gap, cutoff_hz=None if cutoff == "none" else float(cutoff),
                            rate_hz=None if rate == "recording" else float(rate),
                            scale=scale if scale in (None, "auto") else float(scale), angle_scale=angle_scale,
                            max_position_mm=max_residual[0], max_orientation_deg=max_residual[1], max_rigid_mm=max_rigid,
                            min_transmission_deg=min_transmission, force_file=None if force_file is None else str(force_file),
                            fit_registration=fit_registration, keep_spikes=keep_spikes, clip=clip,
                            timing=timing)
    with errors_reported():
        inputs = [recording, registration, force_file, Path(model) if Path(model).suffix.lower() == ".toml" else None]
        for target in (out, residuals, figure, page) + ((found_toml,) if fit_registration else ()):  # before the work, not after it
            check_output(target, force, WRITTEN_FILE, inputs)
        with progress(False, "import-motion", total=STEPS) as step:
            result = run_import(recording, registration, options, progress=step)
        about = f"chewbot import-motion {shlex.join(_arguments(recording, registration, out, options, force))}"
        summary = result.summary()
        files = [(residuals, result.residuals(), {"about": "residuals of " + about, "summary": summary})]
        if result.task is not None:
            files.insert(0, (out, task_table(result.task), "a task, read it with chewbot run --task; from " + about))
        if result.found is not None:
            from chewbot.recordings.registration import registration_toml

            found_lines = [line for line in summary if line.startswith(("detected:", "share ", "prior:", "registration:"))]
            text = registration_toml(result.registration, f"registration found by {about}\n" + "\n".join(found_lines))
            files.append((found_toml, text, "a registration, chewbot import-motion --registration reads it; found by " + about))
        from chewbot.report.recording_figures import incisor_paths_svg

        m = result.measures()
        tracker = (result.registration.rotation, result.registration.origin)
        files.append((figure, incisor_paths_svg(result.recording.t, m.recorded_incisor, m.reproduced_incisor,
                                                f"{recording.name}: recorded (registered, scale 1) and reproduced incisor path", tracker),
                      "the incisor path of " + about))
        from chewbot.report.recording_figures import recording_report_html

        f = result.found
        limiting_t = result.recording.t[f.limiting_frames] if f is not None else result.recording.t[:0]
        files.append((page, recording_report_html(f"{recording.name}: what the robot reproduces", result.recording.t, m,
                                                  f.share if f is not None else result.factor, f.limiting if f is not None else "",
                                                  limiting_t, options.max_position_mm, summary, result.notes, tracker,
                                                  result.registration_rows()),
                      "the report of " + about))
        with atomic_files([path for path, _, _ in files], force, inputs, about={path: what for path, _, what in files}) as temporaries:
            for (path, content, what), tmp in zip(files, temporaries):
                if isinstance(content, str):  # the registration (TOML) and the figure (SVG) carry the marker line
                    comment = "<!--" if path.suffix in (".svg", ".html") else "#"
                    Path(tmp).write_text(marker_line(comment, what) + "\n" + content, encoding="utf-8")
                else:
                    content.to_csv(tmp)
    for note in result.notes:
        console.print(f"note: {note}", highlight=False, markup=False)
    _print_maxima(stdout, result)
    for line in summary:
        stdout.print(line, highlight=False, markup=False)
    if result.found is not None:
        stdout.print(f"wrote the registration found: {found_toml}", highlight=False, markup=False)
    if result.task is None:
        lines = result.failures()
        shown = lines[:10] + ([f"... and {len(lines) - 10} more stretch(es): see {residuals}"] if len(lines) > 10 else [])
        fail(FitError(f"{(~result.passed).sum()} of {result.recording.n} frame(s) fail; {out} not written, "
                       f"residuals in {residuals}:\n" + "\n".join(shown)), EXIT_UNREACHABLE)
    stdout.print(f"wrote {out} ({result.task.n} samples), {residuals}, {figure} and {page}; run it with: "
                 f"chewbot run --task {shlex.quote(str(out))} --model {shlex.quote(model)} --side {side}", highlight=False, markup=False)


def _arguments(recording, registration, out, options, force: bool) -> list[str]:
    """The command's effective arguments, defaults included: the header line of both files."""
    o = options
    args = [str(recording), "--registration", str(registration), "--out", str(out), "--model", o.model, "--side", o.side,
            "--max-gap", f"{o.max_gap_s:g}", "--cutoff", "none" if o.cutoff_hz is None else f"{o.cutoff_hz:g}",
            "--rate", "recording" if o.rate_hz is None else f"{o.rate_hz:g}"]
    if o.scale is not None:
        args += ["--scale", str(o.scale)]
    if o.angle_scale is not None:
        args += ["--angle-scale", f"{o.angle_scale:g}"]
    args += ["--max-residual", f"{o.max_position_mm:g}", f"{o.max_orientation_deg:g}", "--max-rigid", f"{o.max_rigid_mm:g}",
             "--min-transmission", f"{o.min_transmission_deg:g}"]
    if o.force_file is not None:
        args += ["--force-file", o.force_file]
    if o.fit_registration:
        args.append("--fit-registration")
    if o.keep_spikes:
        args.append("--keep-spikes")
    if o.clip:
        args.append("--clip")
    args += ["--timing", o.timing]
    return args + (["--force"] if force else [])


def _print_maxima(stdout, result) -> None:
    """The largest residuals, with where they occur, and the scale that was used."""
    import numpy as np

    rec, fit, rigid = result.recording, result.fit, result.rigid
    k = int(np.argmax(rigid.max_mm))
    marker = rigid.markers[int(np.argmax(rigid.distances[k]))]
    lines = [f"markers' rigid fit: RMS up to {rigid.rms_mm.max():.3g} mm; largest {rigid.max_mm[k]:.3g} mm (marker {marker}, {rec.where(k)})"]
    if fit.admissible.any():
        i, j = int(np.nanargmax(fit.position_error_mm)), int(np.nanargmax(fit.orientation_error_deg))
        lines.append(f"robot fit: position error up to {fit.position_error_mm[i]:.3g} mm ({rec.where(i)}), "
                     f"orientation error up to {fit.orientation_error_deg[j]:.3g} deg ({rec.where(j)})")
    outside = fit.outside.any(axis=1)
    if outside.any():
        names = [n for n, b in zip(fit.constraint_names, fit.outside.any(axis=0)) if b]
        lines.append(f"the recorded motion leaves the workspace in {outside.sum()} frame(s) ({', '.join(names)}); there the "
                     "nearest pose on its boundary is used")
    if result.factor is not None:
        angle = "" if result.registration.point_path else f", angle_scale {result.angle_scale:.4g}"  # a point has no rotation to scale
        what = "--scale auto" if result.options.scale == "auto" else "the task's factor of the share"
        lines.append(f"{what}: factor {result.factor:.4f} (scale {result.scale:.4g}{angle})")
    for line in lines:
        stdout.print(line, highlight=False, markup=False)
