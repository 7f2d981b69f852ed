"""Files the project reads and writes, handled safely.

Reading: regular files only (a symbolic link, FIFO, device, socket or folder is refused before
anything is read; links are not followed, `O_NOFOLLOW`), a size cap checked before reading or
hashing, hashes streamed in chunks, and JSON parsed with its failures (bad UTF-8, bad syntax,
nesting too deep for the parser, over-long integers) reported as one error. Writing: a new file
opened exclusively without following links and fsynced; `write_atomic` replaces a file whole
or not at all and leaves no temporary file behind on failure.

Every reader takes the error type to raise (`PolicyFormatError`, `ResultFileError`, ...), so
each caller reports its own kind of failure with the file's name and the cause.
"""

from __future__ import annotations

import errno
import hashlib
import json
import os
import shutil
import stat
from collections.abc import Iterator
from pathlib import Path
from typing import Any

CHUNK_BYTES = 1 << 20
"""Bytes hashed or read per system call."""
_KINDS = (
    (stat.S_ISDIR, "a folder"),
    (stat.S_ISLNK, "a symbolic link"),
    (stat.S_ISFIFO, "a FIFO"),
    (stat.S_ISCHR, "a character device"),
    (stat.S_ISBLK, "a block device"),
    (stat.S_ISSOCK, "a socket"),
)


def kind(mode: int) -> str:
    """What a file of this `st_mode` is, in words."""
    return next((name for test, name in _KINDS if test(mode)), "not a regular file")


def open_regular(path: Path, error: type[Exception]) -> int:
    """A read-only descriptor of `path`, which must be a regular file (not followed if a link).

    Raises:
        error: the file is missing, unreadable, a symbolic link or not a regular file.
    """
    flags = os.O_RDONLY | os.O_NOFOLLOW | os.O_NONBLOCK | os.O_CLOEXEC  # a FIFO does not block
    try:
        fd = os.open(path, flags)
    except FileNotFoundError as exc:
        raise error(f"{path} is missing") from exc
    except OSError as exc:
        if exc.errno == errno.ELOOP:
            raise error(f"{path} is a symbolic link: accepted a regular file only") from exc
        raise error(f"{path} cannot be read: {exc.strerror or exc}") from exc
    mode = os.fstat(fd).st_mode
    if not stat.S_ISREG(mode):
        os.close(fd)
        raise error(f"{path} is {kind(mode)}: accepted a regular file only")
    return fd


def _check_size(fd: int, path: Path, cap_bytes: int, error: type[Exception]) -> int:
    size = os.fstat(fd).st_size
    if size > cap_bytes:
        raise error(f"{path} holds {size} bytes: accepted at most {cap_bytes}")
    return size


def _chunks(fd: int, path: Path, error: type[Exception]) -> Iterator[bytes]:
    while True:
        try:
            chunk = os.read(fd, CHUNK_BYTES)
        except OSError as exc:  # EIO, EISDIR...: the cause in the message, no traceback
            raise error(f"{path} cannot be read: {exc.strerror or exc}") from exc
        if not chunk:
            return
        yield chunk


def read_capped(path: Path, cap_bytes: int, error: type[Exception]) -> bytes:
    """The bytes of a regular file of at most `cap_bytes` (checked before reading, and again
    while reading: a file that grows is refused too)."""
    fd = open_regular(path, error)
    try:
        _check_size(fd, path, cap_bytes, error)
        chunks, total = [], 0
        for chunk in _chunks(fd, path, error):
            total += len(chunk)
            if total > cap_bytes:
                raise error(f"{path} holds more than {cap_bytes} bytes: accepted at most that")
            chunks.append(chunk)
    finally:
        os.close(fd)
    return b"".join(chunks)


def sha256_file(path: Path, cap_bytes: int, error: type[Exception]) -> str:
    """SHA-256 of a regular file, streamed in chunks; a file over `cap_bytes` is refused
    before any byte is hashed."""
    fd = open_regular(path, error)
    digest = hashlib.sha256()
    try:
        _check_size(fd, path, cap_bytes, error)
        for chunk in _chunks(fd, path, error):
            digest.update(chunk)
    finally:
        os.close(fd)
    return digest.hexdigest()


def parse_json(data: bytes, path: Path, error: type[Exception]) -> Any:
    """JSON from bytes read from `path`; every parse failure as one `error`."""
    try:
        return json.loads(data.decode("utf-8"))
    except UnicodeDecodeError as exc:
        raise error(f"{path} is not UTF-8 text: {exc}") from exc
    except RecursionError as exc:
        raise error(f"{path} is nested too deeply to be read as JSON") from exc
    except ValueError as exc:  # JSONDecodeError, and integers over the interpreter's digit limit
        raise error(f"{path} is not valid JSON: {exc}") from exc


def read_json(path: Path, cap_bytes: int, error: type[Exception]) -> Any:
    """A JSON file, read with `read_capped` and `parse_json`."""
    return parse_json(read_capped(path, cap_bytes, error), path, error)


def write_new(path: Path, data: bytes) -> None:
    """Create `path` (it must not exist; a link there is not followed) holding `data`, fsynced.

    Raises:
        OSError: the write failed (no space left, file too large, read-only...); the partial
            file is removed.
    """
    fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_EXCL | os.O_NOFOLLOW | os.O_CLOEXEC, 0o644)
    try:
        view = memoryview(data)
        while view:
            view = view[os.write(fd, view) :]
        os.fsync(fd)
    except BaseException:
        os.close(fd)
        path.unlink(missing_ok=True)
        raise
    os.close(fd)


def write_atomic(path: Path, data: bytes) -> None:
    """Replace `path` whole or not at all: `<path>.tmp` written and fsynced, then renamed.

    Raises:
        OSError: the write failed; `path` is unchanged and no `<path>.tmp` is left.
    """
    tmp = path.with_name(path.name + ".tmp")
    remove(tmp)
    write_new(tmp, data)
    try:
        tmp.replace(path)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise


def fsync_dir(folder: Path) -> None:
    """Make the renames and creations inside `folder` durable."""
    fd = os.open(folder, os.O_RDONLY | os.O_DIRECTORY)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)


def remove(path: Path) -> None:
    """Remove a file, a link (not what it points to) or a folder tree; nothing if absent."""
    try:
        mode = os.lstat(path).st_mode
    except FileNotFoundError:
        return
    if stat.S_ISDIR(mode):
        shutil.rmtree(path)
    else:
        path.unlink(missing_ok=True)
