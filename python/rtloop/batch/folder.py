"""A batch's output folder: the job folders it made (each holds a marker file, and only those are ever
replaced), its lock (one batch at a time) and results.jsonl (read only when a regular file, appended a whole
line at a time)."""

from __future__ import annotations

import contextlib
import errno
import fcntl
import json
import os
import stat
from collections.abc import Iterable, Iterator
from pathlib import Path
from typing import Any

from ..errors import RtloopError

__all__ = ["LOCK", "MARKER", "Results", "check_targets", "locked", "mark", "may_replace"]

#: The file inside every job folder a batch writes: a folder without it is never replaced.
MARKER = ".rtloop-batch-job"
#: The lock file in the output folder (flock): a second batch on the folder stops with one line.
LOCK = ".rtloop-batch.lock"
#: The most bytes of results.jsonl read (a line is a few hundred bytes: room for millions of jobs).
MAX_RESULTS = 1 << 31


def mark(folder: Path) -> None:
    """Mark a staged job folder as the batch's."""
    (folder / MARKER).write_text("a job folder written by rtloop-fit --batch\n", encoding="utf-8")


def may_replace(target: Path) -> bool:
    """False where nothing is at ``target``; True where a job folder the batch wrote is; else an error."""
    if not os.path.lexists(target):
        return False
    if target.is_dir() and not target.is_symlink() and (target / MARKER).is_file():
        return True
    what = "a symbolic link" if target.is_symlink() else "a folder" if target.is_dir() else "a file"
    raise RtloopError(f"{target}: {what} not written by rtloop-fit --batch is in the way of job "
                      f"{target.name!r} (it has no {MARKER}); move it or rename the job")


def check_targets(out: Path, ids: Iterable[str]) -> None:
    """Refuse, before any fit, a job whose folder would replace something the batch did not write."""
    for jid in ids:
        may_replace(out / jid)


@contextlib.contextmanager
def locked(out: Path) -> Iterator[None]:
    """Hold ``out``/.rtloop-batch.lock (fcntl.flock, released when the process ends however it ends)."""
    path = out / LOCK
    try:
        fd = os.open(path, os.O_RDWR | os.O_CREAT | os.O_NOFOLLOW | os.O_NONBLOCK | os.O_CLOEXEC, 0o666)
    except OSError as e:
        raise RtloopError(f"{path}: cannot open the lock file ({e.strerror or e})") from None
    try:
        if not stat.S_ISREG(os.fstat(fd).st_mode):
            raise RtloopError(f"{path}: the lock file is not a regular file")
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError as e:
            if e.errno in (errno.EWOULDBLOCK, errno.EAGAIN, errno.EACCES):
                raise RtloopError(f"{out}: another batch is running on this output directory (it holds "
                                  f"{LOCK}); wait for it to end") from None
            raise RtloopError(f"{path}: cannot lock ({e.strerror or e})") from None
        yield
    finally:
        os.close(fd)


class Results:
    """``DIR/results.jsonl``: the records already there, and whole-line appends (one write, then fsync).
    Only a regular file is read (a link to a device or a FIFO is refused); a torn last line is dropped."""

    def __init__(self, path: Path):
        self.path = path
        self.done: dict[str, dict[str, Any]] = {}
        try:
            self.fd = os.open(path, os.O_RDWR | os.O_APPEND | os.O_CREAT | os.O_NONBLOCK | os.O_CLOEXEC, 0o666)
        except OSError as e:
            raise RtloopError(f"{path}: cannot open ({e.strerror or e})") from None
        try:
            self._read()
        except BaseException:
            os.close(self.fd)
            raise

    def _read(self) -> None:
        info = os.fstat(self.fd)
        if not stat.S_ISREG(info.st_mode):
            raise RtloopError(f"{self.path}: not a regular file; the batch keeps its results there")
        if info.st_size > MAX_RESULTS:
            raise RtloopError(f"{self.path}: larger than {MAX_RESULTS} bytes; start a new output directory")
        data = os.pread(self.fd, info.st_size, 0)
        end = data.rfind(b"\n") + 1
        if end < len(data):  # a torn last line (a crash mid-write elsewhere): drop it
            os.ftruncate(self.fd, end)
        for line in data[:end].decode("utf-8", "replace").splitlines():
            try:
                rec = json.loads(line)
            except (ValueError, RecursionError):
                continue
            if isinstance(rec, dict) and isinstance(rec.get("id"), str):
                self.done[rec["id"]] = rec

    def skip(self, retry_failed: bool) -> dict[str, str]:
        """``{id: hash}`` of the jobs recorded as done (ok, or failed unless ``retry_failed``)."""
        return {i: r["hash"] for i, r in self.done.items()
                if isinstance(r.get("hash"), str) and (r.get("status") == "ok" or not retry_failed)}

    def fitted(self) -> dict[str, dict[str, float]]:
        """``{id: x}`` of the jobs recorded as ok (a warm-started chain resumes from them)."""
        return {i: r["x"] for i, r in self.done.items() if r.get("status") == "ok" and isinstance(r.get("x"), dict)}

    def append(self, record: dict[str, Any]) -> None:
        data = (json.dumps(record, allow_nan=False) + "\n").encode("utf-8")
        view = memoryview(data)
        try:
            while view:
                view = view[os.write(self.fd, view):]
            os.fsync(self.fd)
        except OSError as e:
            raise RtloopError(f"{self.path}: cannot append a result ({e.strerror or e})") from None

    def close(self) -> None:
        os.close(self.fd)
