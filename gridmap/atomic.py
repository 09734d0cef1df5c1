"""Writing a file so that it is always either the old file or the new one, complete, and stays
so across a power cut."""

from __future__ import annotations

import io
import os
import threading
from pathlib import Path


def write_atomically(path, content: bytes | str) -> None:
    """Write ``content`` (bytes, or text as UTF-8) to a temporary file beside ``path``, flush it
    to disk, rename it into place and flush the folder's entry too. The temporary file is
    opened like any other (not with mkstemp's owner-only mode), so a map_server running as
    another user can read the result. Raises ``OSError``; no temporary file is left behind."""
    if isinstance(content, str):
        content = content.encode()
    path = Path(path)
    folder = path.resolve().parent
    # unique to this process and thread, so two writers of one path never share it
    tmp = folder / f".{path.name}.{os.getpid()}.{threading.get_ident()}.tmp"
    try:
        with open(tmp, "wb") as f:
            f.write(content)
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, path)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise
    _fsync_folder(folder)


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
