"""Atomic file writes: a reader sees the old file or the whole new one, never a part.

A file is written to a hidden temporary name next to its target (same filesystem), flushed
to disk, then renamed onto the target with :func:`os.replace`. The temporary file gets the
permissions an ordinary new file would have (subject to the umask), unlike
:func:`tempfile.mkstemp`'s 0600.
"""

from __future__ import annotations

import os
import secrets
from pathlib import Path


def new_temporary(target: Path) -> Path:
    """Create an empty hidden file ``.{target.name}.XXXXXXXX.tmp`` next to ``target``."""
    target = Path(target)
    for _ in range(100):
        tmp = target.parent / f".{target.name}.{secrets.token_hex(4)}.tmp"
        try:
            os.close(os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o666))
        except FileExistsError:
            continue
        return tmp
    raise FileExistsError(f"no free temporary name next to {target}")


def fsync(path: Path) -> None:
    """Flush the content of ``path`` to disk, so a rename never exposes a partial file."""
    with open(path, "rb") as f:
        os.fsync(f.fileno())


def write_text_atomic(path: Path, text: str) -> Path:
    """Write ``text`` (UTF-8) to ``path`` atomically."""
    return write_bytes_atomic(path, text.encode("utf-8"))


def write_bytes_atomic(path: Path, data: bytes) -> Path:
    """Write ``data`` to ``path`` atomically."""
    path = Path(path)
    tmp = new_temporary(path)
    try:
        tmp.write_bytes(data)
        fsync(tmp)
        os.replace(tmp, path)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise
    return path
