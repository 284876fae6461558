"""Logging that does not break tqdm progress bars."""

from __future__ import annotations

import logging

from tqdm.auto import tqdm


class TqdmLoggingHandler(logging.Handler):
    """Writes log records through ``tqdm.write`` so active bars are redrawn below them."""

    def emit(self, record: logging.LogRecord) -> None:
        try:
            tqdm.write(self.format(record))
        except Exception:  # noqa: BLE001 - logging must never raise into the caller
            self.handleError(record)


def setup_logging(quiet: bool = False) -> None:
    root = logging.getLogger()
    for handler in list(root.handlers):
        if isinstance(handler, TqdmLoggingHandler):
            root.removeHandler(handler)
    handler = TqdmLoggingHandler()
    handler.setFormatter(logging.Formatter("%(asctime)s %(levelname)-7s %(name)s: %(message)s", "%H:%M:%S"))
    root.addHandler(handler)
    root.setLevel(logging.WARNING if quiet else logging.INFO)
