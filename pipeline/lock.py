"""One writer per run folder: an advisory lock on ``runs/<name>/.lock``.

``pipeline run`` holds the lock exclusively for as long as it writes into the run folder; the shard
jobs of a sharded render (``pipeline shard``) hold it shared, so they run side by side but never
beside a ``pipeline run`` of the same folder. The lock is ``fcntl.flock`` on an open file: the kernel
releases it when the holder's process ends, however it ends (SIGKILL included), so a lock left by a
dead run never blocks the next one. Different run folders (sweep points, other configs) have
different locks and never wait for each other.

The exclusive holder writes who it is (pid, host, command, start time) into the lock file, so that a
run that has to wait, or refuses with ``--no-wait``, can say which run holds the folder. The file is
rewritten in place, never replaced: a rename would give the waiters' open file a different inode
from the holder's, and two runs would both hold "the" lock.
"""

from __future__ import annotations

import contextlib
import errno
import fcntl
import json
import logging
import os
import shlex
import socket
import sys
import time
from collections.abc import Callable, Iterator
from datetime import datetime
from pathlib import Path
from typing import Any

log = logging.getLogger(__name__)

LOCK_NAME = ".lock"
POLL_S = 0.2  # how often a waiting run tries the lock again
REPEAT_S = 60.0  # how often a waiting run repeats its message while the holder stays the same


class RunFolderBusy(RuntimeError):
    """Another process holds the run folder's lock, and the caller asked not to wait."""

    def __init__(self, folder: Path, holder: str) -> None:
        super().__init__(
            f"{folder} is in use by {holder}; wait for it to finish, or run again without --no-wait to wait for it"
        )
        self.folder = folder
        self.holder = holder


def this_process() -> dict[str, Any]:
    """Who holds a lock: pid, host, command line and start time."""
    return {
        "pid": os.getpid(),
        "host": socket.gethostname(),
        "command": shlex.join([Path(sys.orig_argv[0]).name, *sys.orig_argv[1:]]),  # as typed: python -m pipeline ...
        "since": datetime.now().astimezone().isoformat(timespec="seconds"),
    }


def describe_holder(record: dict[str, Any] | None) -> str:
    """``record`` (what the holder wrote in the lock file) in words."""
    if not record:
        return "another process (it has not written its pid yet)"
    since = str(record.get("since", "?"))
    since = since[11:19] if len(since) >= 19 else since  # the time of day; the date is rarely in doubt
    return f"pid {record.get('pid')} on {record.get('host')} since {since} (`{record.get('command')}`)"


def read_holder(path: Path) -> dict[str, Any] | None:
    """What the last exclusive holder of the lock at ``path`` wrote about itself, if it is readable."""
    try:
        record = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return None  # absent, or being rewritten at this moment
    return record if isinstance(record, dict) else None


def _try_lock(fd: int, shared: bool) -> bool:
    try:
        fcntl.flock(fd, (fcntl.LOCK_SH if shared else fcntl.LOCK_EX) | fcntl.LOCK_NB)
    except OSError as exc:
        if exc.errno in (errno.EWOULDBLOCK, errno.EAGAIN, errno.EACCES):
            return False
        raise
    return True


def _who_holds(fd: int, path: Path) -> str:
    """The holder in words, as seen from ``fd``, which failed to take the lock."""
    if _try_lock(fd, shared=True):  # only shared holders: shard jobs, which write no record
        fcntl.flock(fd, fcntl.LOCK_UN)
        return "the shard jobs of a sharded render (`pipeline shard`)"
    return describe_holder(read_holder(path))


@contextlib.contextmanager
def hold_run_folder(
    folder: Path,
    *,
    wait: bool = True,
    shared: bool = False,
    on_wait: Callable[[str], None] | None = None,
) -> Iterator[Path]:
    """Hold the lock of the run folder ``folder`` (created if needed) until the block ends.

    Exclusive by default (``pipeline run``); ``shared`` for the jobs that may run side by side
    (``pipeline shard``). When another process holds it, wait (calling ``on_wait`` with a message that
    names the holder, at once and whenever the holder changes or a minute passes) or, with
    ``wait=False``, raise ``RunFolderBusy``.
    """
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    path = folder / LOCK_NAME
    fd = os.open(path, os.O_RDWR | os.O_CREAT, 0o644)  # not inherited by subprocesses (PEP 446)
    try:
        told, told_at = "", 0.0
        while not _try_lock(fd, shared):
            holder = _who_holds(fd, path)
            if not wait:
                raise RunFolderBusy(folder, holder)
            now = time.monotonic()
            if holder != told or now - told_at >= REPEAT_S:
                message = f"{folder} is in use by {holder}; waiting for it (Ctrl-C to stop; --no-wait refuses at once)"
                (on_wait or log.warning)(message)
                told, told_at = holder, now
            time.sleep(POLL_S)
        if not shared:
            record = (json.dumps(this_process(), sort_keys=True) + "\n").encode("utf-8")
            try:
                os.ftruncate(fd, 0)
                os.pwrite(fd, record, 0)
            except OSError as exc:  # a full disk: the lock holds all the same, only its holder goes unnamed
                log.debug("could not record this run in %s: %s", path, exc)
        yield path
    finally:
        os.close(fd)  # releases the lock


__all__ = ["LOCK_NAME", "RunFolderBusy", "describe_holder", "hold_run_folder", "read_holder"]
