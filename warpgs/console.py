"""What warpgs says on stderr besides its results: each warning once, in one line, and only where it applies.

    warn_once("warpgs: LPIPS not computed: ...")        # printed the first time only (per process)
    with filtered_stderr(["could not load the CUDA driver"]):
        wp.init()                                        # a library's lines that do not apply are dropped

``filtered_stderr`` works on file descriptor 2, so it also catches what native code prints (Warp's C++
start-up, Mesa's EGL); the lines it does not drop are written back to stderr when the block ends.
"""

from __future__ import annotations

import contextlib
import os
import sys
import tempfile
import threading

_said: set[str] = set()
_lock = threading.Lock()


def warn_once(message: str, key: str | None = None) -> bool:
    """Prints ``message`` to stderr unless a message with this ``key`` (default: the message itself) was
    printed before in this process; returns whether it printed."""
    k = message if key is None else key
    with _lock:
        if k in _said:
            return False
        _said.add(k)
    print(message, file=sys.stderr, flush=True)
    return True


@contextlib.contextmanager
def filtered_stderr(drop: list[str]):
    """Runs the block with file descriptor 2 captured; afterwards writes back every line that contains
    none of the strings in ``drop`` (case-insensitive)."""
    try:
        sys.stderr.flush()
        saved = os.dup(2)
    except (OSError, ValueError):  # no real stderr (an embedded interpreter): nothing to filter
        yield
        return
    with tempfile.TemporaryFile() as tmp:
        os.dup2(tmp.fileno(), 2)
        try:
            yield
        finally:
            try:
                sys.stderr.flush()
            except ValueError:
                pass
            os.dup2(saved, 2)
            os.close(saved)
            tmp.seek(0)
            text = tmp.read().decode("utf-8", "replace")
            keep = [ln for ln in text.splitlines(keepends=True)
                    if ln.strip() and not any(d.lower() in ln.lower() for d in drop)]
            if keep:
                sys.stderr.write("".join(keep))
                sys.stderr.flush()


__all__ = ["filtered_stderr", "warn_once"]
