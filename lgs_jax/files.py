"""Files written whole or not at all: `written` gives a temporary name in the destination's
folder and renames it to the destination only when writing succeeded, so an interrupted or
failed write leaves no partial file under the name asked for (a kill may leave the hidden
temporary, `.NAME.XXXX.partial.EXT`)."""

from __future__ import annotations

import contextlib
import os
import tempfile


@contextlib.contextmanager
def written(path: str):
    """Yields a temporary path in `path`'s folder to write; renamed to `path` when the block
    ends without an error, removed otherwise."""
    folder, name = os.path.split(os.path.abspath(path))
    base, ext = os.path.splitext(name)
    fd, tmp = tempfile.mkstemp(prefix=f".{base}.", suffix=f".partial{ext}", dir=folder)
    os.close(fd)
    mask = os.umask(0)
    os.umask(mask)
    os.chmod(tmp, 0o666 & ~mask)  # as `open` would make it (mkstemp's is 0600)
    try:
        yield tmp
        os.replace(tmp, path)
    finally:
        with contextlib.suppress(FileNotFoundError):
            os.remove(tmp)
