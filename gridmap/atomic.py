"""Writing a file so that it is always either the old file or the new one, complete."""

from __future__ import annotations

import os
from pathlib import Path


def write_atomically(path, content: bytes) -> None:
    """Write to a temporary file beside ``path``, flush it to disk and rename it into place.
    The temporary file is opened like any other (not with mkstemp's owner-only mode), so a
    map_server running as another user can read the result. Raises ``OSError``."""
    path = Path(path)
    tmp = path.resolve().parent / f".{path.name}.{os.getpid()}.tmp"
    try:
        with open(tmp, "wb") as f:
            f.write(content)
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, path)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise
