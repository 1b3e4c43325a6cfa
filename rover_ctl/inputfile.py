"""Reading a file a user named (a mission, a config, a rule base, a key): bounded and regular only.

``Path.read_text`` on ``/dev/zero`` reads until memory runs out, and on a FIFO with no writer it
waits for ever, so a wrong path given to a command hung it. Here the file is opened without
blocking, must be a regular file, and is read up to a size no such file comes near; anything else
is an ``OSError`` (its text without the path, as ``strerror``), which every caller already turns
into its one-line error.
"""

from __future__ import annotations

import errno
import os
import stat

MAX_BYTES = 64 * 1024 * 1024
"""The largest input file read: a QGroundControl ``.plan`` of MAVLink's 65,535 mission items at
some 500 bytes each is 33 MB; every other input (config, rule base, parameters, CSV) is far
smaller."""


class InputFileError(OSError):
    """A path that cannot be an input file; ``str()`` is the reason alone."""

    def __init__(self, reason: str) -> None:
        super().__init__(errno.EINVAL, reason)

    def __str__(self) -> str:
        return self.strerror


class NotRegularFile(InputFileError):
    """The path is a device, a FIFO or a socket."""


class FileTooLarge(InputFileError):
    """The file is larger than the limit given."""


def read_bytes(path: str | os.PathLike, max_bytes: int = MAX_BYTES) -> bytes:
    """The file's bytes; ``NotRegularFile`` or ``FileTooLarge`` instead of blocking or filling memory.
    A directory raises ``IsADirectoryError`` as ``open`` does."""
    fd = os.open(path, os.O_RDONLY | os.O_NONBLOCK)  # O_NONBLOCK: opening a FIFO must not wait for a writer
    try:
        mode = os.fstat(fd).st_mode
        if stat.S_ISDIR(mode):
            raise IsADirectoryError(errno.EISDIR, os.strerror(errno.EISDIR), str(path))
        if not stat.S_ISREG(mode):
            raise NotRegularFile("not a regular file")
        chunks, size = [], 0
        while size <= max_bytes:
            chunk = os.read(fd, max_bytes + 1 - size)
            if not chunk:
                break
            chunks.append(chunk)
            size += len(chunk)
    finally:
        os.close(fd)
    if size > max_bytes:
        raise FileTooLarge(f"larger than {max_bytes:,} bytes")
    return b"".join(chunks)


def read_text(path: str | os.PathLike, max_bytes: int = MAX_BYTES, encoding: str = "utf-8") -> str:
    """``read_bytes`` decoded (``UnicodeDecodeError`` as ``bytes.decode`` raises it), newlines
    translated to ``\\n`` as ``Path.read_text`` does."""
    return read_bytes(path, max_bytes).decode(encoding).replace("\r\n", "\n").replace("\r", "\n")
