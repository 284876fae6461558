"""Logging that does not break tqdm progress bars, and each run's log file."""

from __future__ import annotations

import contextlib
import logging
from collections.abc import Iterator
from pathlib import Path

from tqdm.auto import tqdm

# A record with this attribute set goes to the run's log file only (a stage's traceback: the terminal
# gets the one-line error; `pipeline run --debug` prints the traceback there as well).
FILE_ONLY = "file_only"
FORMAT = "%(asctime)s %(levelname)-7s %(name)s: %(message)s"


class TqdmLoggingHandler(logging.Handler):
    """Writes log records through ``tqdm.write`` so active bars are redrawn below them."""

    def __init__(self, level: int = logging.NOTSET) -> None:
        super().__init__(level)
        self.addFilter(lambda record: not getattr(record, FILE_ONLY, False))

    def emit(self, record: logging.LogRecord) -> None:
        try:
            tqdm.write(self.format(record))
        except Exception:  # noqa: BLE001 - logging must never raise into the caller
            self.handleError(record)


def setup_logging(quiet: bool = False) -> None:
    """Progress on the terminal (warnings and errors only when ``quiet``); the run's log file gets INFO."""
    root = logging.getLogger()
    for handler in list(root.handlers):
        if isinstance(handler, TqdmLoggingHandler):
            root.removeHandler(handler)
    handler = TqdmLoggingHandler(logging.WARNING if quiet else logging.INFO)
    handler.setFormatter(logging.Formatter(FORMAT, "%H:%M:%S"))
    root.addHandler(handler)
    root.setLevel(logging.INFO)


class RunLogHandler(logging.FileHandler):
    """A run's log file. When it cannot be written (a full disk), it stops writing, silently: the run's
    own error says what happened, and logging's default report would bury it under a traceback."""

    def handleError(self, record: logging.LogRecord) -> None:
        self.setLevel(logging.CRITICAL + 1)


@contextlib.contextmanager
def log_to_file(path: Path) -> Iterator[Path]:
    """Append what is logged (at the root logger's level) to ``path`` while the block runs.

    A log is appended to, not replaced: each run adds its lines after the last run's."""
    handler = RunLogHandler(path, mode="a", encoding="utf-8")
    handler.setFormatter(logging.Formatter(FORMAT, "%Y-%m-%d %H:%M:%S"))
    root = logging.getLogger()
    root.addHandler(handler)
    try:
        yield path
    finally:
        root.removeHandler(handler)
        handler.close()
