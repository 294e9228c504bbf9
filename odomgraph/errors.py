"""The project's small exception hierarchy. The CLI turns these into one line
on stderr and exit code 1; anything else is a bug and keeps its traceback."""
from __future__ import annotations

from pathlib import Path


class OdomgraphError(Exception):
    """Base class of every error a user can cause or act on."""


class LogFormatError(OdomgraphError):
    """Bad input: names the file, the line (when there is one) and the problem."""

    def __init__(self, path: Path | str, problem: str, line: int | None = None):
        self.path, self.problem, self.line = Path(path), problem, line
        where = f"{self.path}:{line}" if line is not None else f"{self.path}"
        super().__init__(f"{where}: {problem}")


class EstimatorDivergedError(OdomgraphError):
    """An estimator detected that its solution is no longer meaningful."""


class OutputDirError(OdomgraphError):
    """The output directory cannot be written safely."""


class OptionError(OdomgraphError):
    """An option or parameter outside its declared range (odomgraph.checks)."""


class NotEnoughDataError(OdomgraphError):
    """The log is valid, but too short or too sparse for what was asked."""


class CalibrationRejectedError(OdomgraphError):
    """``calibrate`` found a problem with its own result and wrote nothing."""
