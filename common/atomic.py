"""Atomic file output: nothing is visible under its final name until it is complete.

Every writer here writes a temporary file in the destination folder, flushes it to disk and
renames it over the final name (``os.replace`` is atomic on POSIX within one file system).
"""

from __future__ import annotations

import contextlib
import json
import os
import re
import secrets
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np


def _temporary_sibling(path: Path) -> Path:
    # Keep the suffix: several libraries (OpenImageIO, PyAV, matplotlib) pick the format from it.
    return path.with_name(f".{path.stem}.tmp-{os.getpid()}-{secrets.token_hex(4)}{path.suffix}")


_TEMPORARY = re.compile(r"^\.(?P<stem>.+)\.tmp-\d+-[0-9a-f]{8}(?P<suffix>.*)$")


def final_path(path: str | os.PathLike[str]) -> Path:
    """The name a temporary file of ``atomic_path`` is renamed to (``path`` itself for any other file):
    what an error message should name."""
    path = Path(path)
    match = _TEMPORARY.match(path.name)
    return path.with_name(match["stem"] + match["suffix"]) if match else path


def _fsync_file(path: Path) -> None:
    fd = os.open(path, os.O_RDONLY)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)


@contextlib.contextmanager
def atomic_path(path: str | os.PathLike[str]) -> Iterator[Path]:
    """Yield a temporary path to write; on success it is renamed to ``path``, on error removed."""
    final = Path(path)
    final.parent.mkdir(parents=True, exist_ok=True)
    tmp = _temporary_sibling(final)
    try:
        yield tmp
        if not tmp.exists():
            raise FileNotFoundError(f"nothing was written to the temporary file for {final}")
        _fsync_file(tmp)
        os.replace(tmp, final)
    finally:
        with contextlib.suppress(FileNotFoundError):
            tmp.unlink()


def write_bytes_atomic(path: str | os.PathLike[str], data: bytes) -> Path:
    with atomic_path(path) as tmp:
        tmp.write_bytes(data)
    return Path(path)


def write_text_atomic(path: str | os.PathLike[str], text: str) -> Path:
    return write_bytes_atomic(path, text.encode("utf-8"))


def write_json_atomic(path: str | os.PathLike[str], obj: Any) -> Path:
    return write_text_atomic(path, json.dumps(obj, indent=2, sort_keys=True, default=_json_default) + "\n")


def save_npy_atomic(path: str | os.PathLike[str], array: np.ndarray) -> Path:
    with atomic_path(path) as tmp:
        with open(tmp, "wb") as f:
            np.save(f, array, allow_pickle=False)
    return Path(path)


def save_figure_atomic(fig: Any, path: Path, *, pdf: bool = False) -> list[Path]:
    """A matplotlib figure as PNG at ``path`` (150 dpi, tight) and, with ``pdf``, beside it as PDF; the caller
    closes the figure."""
    written = []
    for target in [path] + ([path.with_suffix(".pdf")] if pdf else []):
        with atomic_path(target) as tmp:
            fig.savefig(tmp, dpi=150, bbox_inches="tight")
        written.append(target)
    return written


def _json_default(obj: Any) -> Any:
    if isinstance(obj, np.generic):
        return obj.item()
    if isinstance(obj, np.ndarray):
        return obj.tolist()
    if isinstance(obj, Path):
        return str(obj)
    raise TypeError(f"cannot serialise {type(obj).__name__} to JSON")
