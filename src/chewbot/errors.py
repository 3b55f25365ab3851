"""The errors chewbot raises for bad input: each names where the problem is and why."""

from __future__ import annotations


class ChewbotError(Exception):
    """Base class of every error chewbot raises on purpose (bad input, unreachable poses, ...)."""


class ParameterError(ChewbotError):
    """A parameter file is missing, malformed or physically inconsistent.

    The message names the file and the key.
    """


class TaskError(ChewbotError):
    """A task (a CSV file or generator parameters) is malformed: names the file, row or column."""


class KinematicsError(ChewbotError):
    """A pose of the task cannot be reached, leaves the workspace or is singular.

    ``sample`` (0-based row of the task) and ``chain`` (1-based, or None) tell where; ``reason`` is the message
    without them. :meth:`located` adds the task file and its line.
    """

    def __init__(self, message: str, sample: int | None = None, chain: int | None = None, time: float | None = None,
                 location: str | None = None):
        where = []
        if sample is not None:
            where.append(f"sample {sample}")
        if time is not None:
            where.append(f"t = {time:.6g} s")
        if chain is not None:
            where.append(f"chain {chain}")
        prefix = ", ".join(where)
        text = f"{prefix}: {message}" if prefix else message
        super().__init__(f"{location}: {text}" if location else text)
        self.reason, self.sample, self.chain, self.time = message, sample, chain, time

    def located(self, location: str) -> KinematicsError:
        """The same error with ``location`` (e.g. ``"task.csv: line 12"``) in front."""
        return KinematicsError(self.reason, self.sample, self.chain, self.time, location)


class InfeasibleError(ChewbotError):
    """No admissible torque distribution exists at a sample (names the sample and the limit)."""


class RecordingError(ChewbotError):
    """A recording, its registration file or a force file is malformed or cannot be used: names the file and the
    key, line, column, marker or frame."""


class FitError(KinematicsError):
    """Frames of a recording that the robot cannot follow within the tolerances (names the frames and why)."""
