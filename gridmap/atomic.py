"""Writing a file so that it is always either the old file or the new one, complete, and stays
so across a power cut."""

from __future__ import annotations

import errno
import io
import os
import threading
from pathlib import Path


def write_atomically(path, content: bytes | str) -> None:
    """Write ``content`` (bytes, or text as UTF-8) to a temporary file beside ``path``, flush it
    to disk, rename it into place and flush the folder's entry too. A ``path`` that is a
    symbolic link is written through: the file it points to is replaced and the link stays.
    The temporary file is opened like any other (not with mkstemp's owner-only mode), so a
    map_server running as another user can read the result. Raises ``OSError``; no temporary
    file is left behind."""
    if isinstance(content, str):
        content = content.encode()
    # The temporary file goes beside the file the link points to, not beside the link: a
    # rename cannot cross file systems, and a link into another one (/dev/shm, a mounted
    # disk) would fail with EXDEV only after the work was done.
    target = _resolved(Path(path))
    folder = target.parent
    # unique to this process and thread, so two writers of one path never share it
    tmp = folder / f".{target.name}.{os.getpid()}.{threading.get_ident()}.tmp"
    try:
        with open(tmp, "wb") as f:
            f.write(content)
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, target)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise
    _fsync_folder(folder)


def _resolved(path: Path) -> Path:
    """``path`` with every link followed, a dangling one too (the file is made where it
    points); a loop of links is an ``OSError`` like any other unusable path."""
    try:
        return path.resolve()
    except RuntimeError:        # Python before 3.13 reports a loop so
        raise OSError(errno.ELOOP, os.strerror(errno.ELOOP), str(path)) from None


def write_with(path, write) -> None:
    """``write(file)`` into memory, then ``write_atomically``: for writers that want a file
    object (``numpy.savez``, ``Figure.savefig``)."""
    buffer = io.BytesIO()
    write(buffer)
    write_atomically(path, buffer.getvalue())


def _fsync_folder(folder: Path) -> None:
    # The rename is on disk only once the folder is. Windows cannot open a folder for this,
    # and some file systems refuse to sync one; the file itself is already complete then.
    if os.name == "nt":
        return
    fd = os.open(folder, os.O_RDONLY)
    try:
        os.fsync(fd)
    except OSError:
        pass
    finally:
        os.close(fd)
