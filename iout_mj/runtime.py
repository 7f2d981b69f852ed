"""What a run may take from the machine: CPUs for threads and worker processes, and its output
folder, held alone for as long as the run writes there.

Light on purpose (standard library only): the command line imports it before any work.
"""

from __future__ import annotations

import fcntl
import operator
import os
import time
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

from iout_mj.errors import IoutError, UsageError

LOCK_NAME = ".lock"
"""The file in an output folder that a run holds (`fcntl.flock`) while it writes there."""


class OutputBusyError(IoutError):
    """Another run is writing into the same output folder."""


def usable_cpus() -> int:
    """The CPUs this process may run on (its affinity mask, else the machine's count)."""
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # no affinity masks on this platform
        return os.cpu_count() or 1


def cpu_bounded(value: object, name: str, low: int) -> int:
    """`value` as an int if it is an integer from `low` to `usable_cpus()`: more threads or
    worker processes than CPUs only wait for one another and take memory."""
    cpus = usable_cpus()
    try:
        number = None if isinstance(value, bool) else operator.index(value)  # type: ignore[arg-type]
    except TypeError:
        number = None
    if number is None or not low <= number <= cpus:
        raise UsageError(
            f"{name}={value!r} is invalid: accepted an integer from {low} to {cpus} "
            f"(the CPUs this process may use)"
        )
    return number


@contextmanager
def output_lock(folder: Path, command: str) -> Iterator[Path]:
    """Hold `folder/.lock` alone while the body runs: a second run into the same folder is
    refused at once (`OutputBusyError`, naming the run that holds it). The operating system
    releases the lock when the process ends, however it ends (exit, exception, kill)."""
    path = folder / LOCK_NAME
    try:
        fd = os.open(path, os.O_RDWR | os.O_CREAT | os.O_CLOEXEC | os.O_NOFOLLOW, 0o644)
    except OSError as exc:
        raise UsageError(f"cannot write to {folder}: {exc.strerror or exc}") from exc
    try:
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            holder = os.pread(fd, 200, 0).decode(errors="replace").strip() or "another run"
            raise OutputBusyError(
                f"{folder} is in use by {holder}: wait until it ends, or give another output folder"
            ) from None
        os.ftruncate(fd, 0)
        stamp = time.strftime("%Y-%m-%d %H:%M:%S")
        os.pwrite(fd, f"iout-mj {command} (pid {os.getpid()}, since {stamp})\n".encode(), 0)
        yield folder
    finally:
        os.close(fd)
