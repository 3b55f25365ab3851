"""The registration file: how a recording's markers sit on the mandible, where the tracker is, and how the
motion is scaled and weighed for the robot (TOML, validated like the parameter files).

```toml
units = "mm"                   # length unit of the markers, the origin, and of files that carry none
rest = "first"                 # or a [markers] table: NAME = [x, y, z] in {M}
scale = 1.0                    # displacement of O_M relative to the first frame (optional, default 1)
angle_scale = 1.0              # rotation angle relative to the first frame (optional, default 1)

[tracker]                      # optional: p_S = rotation . p_T + origin
rotation = [[1, 0, 0], [0, 1, 0], [0, 0, 1]]
origin = [0, 0, 0]

[fit]                          # optional
position_weight_per_mm = 1.0
orientation_weight_per_deg = 1.0
point_mm = [80, 0, -25]        # default: the model's incisal point
```

Every error is a :class:`~chewbot.errors.RecordingError` naming the file and the key.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Annotated, Literal

import numpy as np
from pydantic import Field, field_validator

from chewbot.config import Strict, key_error, read_text, validate
from chewbot.errors import RecordingError
from chewbot.model.params import POSITION, ROTATION_TOLERANCE
from chewbot.recordings.formats import known_length_units, length_factor
from chewbot.units import factor

Vec3 = Annotated[list[float], Field(min_length=3, max_length=3)]
Mat3 = Annotated[list[Vec3], Field(min_length=3, max_length=3)]
# Markers closer to a line than this (second singular value of their centred positions over the first) do not
# fix a rotation about that line.
COLLINEAR_TOLERANCE = 1e-3


class TrackerSection(Strict):
    rotation: Mat3 = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]
    origin: Vec3 = [0.0, 0.0, 0.0]


class FitSection(Strict):
    position_weight_per_mm: float = Field(1.0, gt=0)
    orientation_weight_per_deg: float = Field(1.0, gt=0)
    point_mm: Annotated[Vec3, POSITION] | None = None


# Landmarks a lab may digitise at the rest frame, each mapped to the model's point of the same name.
LANDMARKS = ("incisor", "molar_left", "molar_right", "condyle_left", "condyle_right")


class LandmarksSection(Strict):
    incisor: Vec3 | None = None
    molar_left: Vec3 | None = None
    molar_right: Vec3 | None = None
    condyle_left: Vec3 | None = None
    condyle_right: Vec3 | None = None


class RegistrationFile(Strict):
    """The TOML file as written."""

    DOCS = "docs/recordings.md"

    units: str
    markers: dict[str, Vec3] | None = None
    rest: Literal["first"] | None = None
    # what the recording tracks: a rigid body, or the point of the mandible (a LANDMARKS name) whose path the markers
    # give (one marker, or several moving in parallel); without the key it is detected (recordings.anatomy.detect)
    tracked: Literal["rigid", "incisor", "molar_left", "molar_right", "condyle_left", "condyle_right"] | None = None
    landmarks: LandmarksSection | None = None
    tracker: TrackerSection = TrackerSection()
    scale: float = Field(1.0, gt=0)
    angle_scale: float = Field(1.0, gt=0)
    fit: FitSection = FitSection()

    @field_validator("units")
    @classmethod
    def _length_unit(cls, v: str) -> str:
        if v not in known_length_units():
            raise ValueError(f"{v!r} is not a length unit (known: {', '.join(known_length_units())})")
        return v


@dataclass(frozen=True, eq=False)
class Registration:
    """A validated registration, SI: ``markers`` {name: position in {M} (m)} or None for ``rest = "first"``;
    ``rotation`` (3, 3) and ``origin`` (3,) m with p_S = rotation p_T + origin; ``point`` (3,) m in {M} or None
    (the model's incisal point); weights per mm and per degree; ``landmarks``: digitised points of the mandible
    at the rest frame in the tracker's frame (m), by the name of the model's point they are (:data:`LANDMARKS`),
    or None; ``tracked``: "rigid", the name of the point of the mandible whose path the markers give (a
    :data:`LANDMARKS` name), or None: detected from the recording."""

    source: str
    units: str
    markers: dict[str, np.ndarray] | None
    rotation: np.ndarray
    origin: np.ndarray
    scale: float
    angle_scale: float
    position_weight_per_mm: float
    orientation_weight_per_deg: float
    point: np.ndarray | None
    landmarks: dict[str, np.ndarray] | None = None  # name: position (m) in the tracker's frame at the rest frame
    tracked: str | None = None  # "rigid", a landmark's name (a point path) or None (detected from the recording)

    @property
    def point_path(self) -> bool:
        """The recording is the path of one point of the mandible (``tracked`` names it)."""
        return self.tracked not in (None, "rigid")


def load_registration(path: str | Path) -> Registration:
    """Read and validate a registration file."""
    text = read_text(path, "registration file", RecordingError)
    return registration_from_dict(text.data, str(text.path))


def registration_from_dict(raw: dict, source: str = "<dict>") -> Registration:
    """Validate a parsed registration file and convert it to SI."""
    f = validate(RegistrationFile, raw, source, RecordingError)

    def fail(key: str, reason: str):
        raise key_error(source, key, reason, RecordingError)

    if f.tracked not in (None, "rigid"):
        if f.markers is not None or f.landmarks is not None or f.fit.point_mm is not None:
            fail("tracked", f"tracked = \"{f.tracked}\": the recording's markers give the path of that point, carried into "
                 "{S} by [tracker]; it takes no [markers], [landmarks] or [fit] point_mm (rest, [tracker], scale and the "
                 "[fit] weights it takes)")
        return Registration(source, f.units, None, _rotation(f.tracker.rotation, fail), np.array(f.tracker.origin) * length_factor(f.units, source),
                            f.scale, f.angle_scale, f.fit.position_weight_per_mm, f.fit.orientation_weight_per_deg,
                            None, None, f.tracked)
    if (f.markers is None) == (f.rest is None):
        fail("markers" if f.markers is None else "rest", "give either a [markers] table (each marker's position in {M}) "
             "or rest = \"first\" (the first frame defines the markers and is the home pose), not both or neither")
    unit = length_factor(f.units, f"{source}: key 'units'")
    landmarks = None
    if f.landmarks is not None:
        landmarks = {name: np.array(v) * unit for name, v in f.landmarks.model_dump().items() if v is not None}
        if f.rest is None:
            fail("landmarks", "landmarks are digitised at the rest frame, the first of the recording: use them with rest = \"first\"")
        if len(landmarks) < 3 or collinear(np.array(list(landmarks.values()))):
            fail("landmarks", f"{len(landmarks)} landmark(s) ({', '.join(landmarks) or 'none'}); the mandible's rest pose needs "
                 f"at least 3 not on one line, of {', '.join(LANDMARKS)}")
    markers = None
    if f.markers is not None:
        if len(f.markers) < 3:
            fail("markers", f"{len(f.markers)} marker(s); the pose of {{M}} needs at least 3 that are not on one line")
        markers = {name: np.array(v) * unit for name, v in f.markers.items()}
        if collinear(np.array(list(markers.values()))):
            fail("markers", "the markers lie on one line (or nearly): they do not fix a rotation about it")
    return Registration(source, f.units, markers, _rotation(f.tracker.rotation, fail), np.array(f.tracker.origin) * unit, f.scale, f.angle_scale,
                        f.fit.position_weight_per_mm, f.fit.orientation_weight_per_deg,
                        None if f.fit.point_mm is None else np.array(f.fit.point_mm) * factor("mm"), landmarks,
                        "rigid" if f.markers is not None or landmarks is not None else f.tracked)


def _rotation(rows, fail) -> np.ndarray:
    """The tracker's rotation, checked, as the nearest rotation (the rows are typically rounded)."""
    rotation = np.array(rows)
    dev = np.abs(rotation.T @ rotation - np.eye(3)).max()
    if dev > ROTATION_TOLERANCE or np.linalg.det(rotation) <= 0:
        fail("tracker.rotation", f"not a rotation matrix (max |R^T R - I| = {dev:.3g}, det = {np.linalg.det(rotation):.4g}); "
             "its columns are the tracker's axes in {S}")
    u, _, vt = np.linalg.svd(rotation)
    return u @ vt


def collinear(points: np.ndarray) -> bool:
    """True when the points (K, 3) lie on one line (or nearly: :data:`COLLINEAR_TOLERANCE`)."""
    sv = np.linalg.svd(points - points.mean(axis=0), compute_uv=False)
    return len(sv) < 2 or sv[1] <= COLLINEAR_TOLERANCE * sv[0]


def registration_toml(reg: Registration, comment: str) -> str:
    """A registration file (TOML, millimetres) holding ``reg``'s tracker, markers in {M}, scales and fit settings,
    with ``comment`` (lines) above: what :func:`load_registration` reads back to the same registration."""

    def vec(v) -> str:
        return "[" + ", ".join(repr(float(x)) for x in v) + "]"

    mm = factor("mm")

    lines = [f"# {line}" for line in comment.splitlines()]
    lines += ['units = "mm"', f"scale = {float(reg.scale)!r}", f"angle_scale = {float(reg.angle_scale)!r}"]
    if reg.tracked is not None:
        lines += [f'tracked = "{reg.tracked}"']
    if not reg.point_path:
        lines += ["", "[markers]"] + [f"{name} = {vec(np.asarray(p) / mm)}" for name, p in (reg.markers or {}).items()]
    lines += ["", "[tracker]", "rotation = [" + ",\n            ".join(vec(row) for row in reg.rotation) + "]",
              f"origin = {vec(reg.origin / mm)}", "", "[fit]", f"position_weight_per_mm = {float(reg.position_weight_per_mm)!r}",
              f"orientation_weight_per_deg = {float(reg.orientation_weight_per_deg)!r}"]
    if reg.point is not None:
        lines.append(f"point_mm = {vec(reg.point / mm)}")
    return "\n".join(lines) + "\n"
