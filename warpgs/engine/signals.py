"""Graceful stops: Ctrl-C (SIGINT) and SIGTERM take one path. The first signal asks the trainer to finish
the current step, write a checkpoint and the outputs' resume note, and stop (``TrainingInterrupted``, whose
``signum`` gives the process's exit code, 128 + the signal: 130 for SIGINT, 143 for SIGTERM); a second one
stops at once (``KeyboardInterrupt``), keeping the last checkpoint on disk. A long phase (the full method's
pseudo-view generation) polls ``requested`` between its pieces of work."""

from __future__ import annotations

import re
import signal
import threading

SIGNALS = (signal.SIGINT, signal.SIGTERM)
_NAMES = {signal.SIGINT: "Ctrl-C", signal.SIGTERM: "SIGTERM"}


class Terminated(KeyboardInterrupt):
    """SIGTERM where Ctrl-C raises ``KeyboardInterrupt`` (outside training, or a second signal)."""

    signum = signal.SIGTERM


def _interrupt(signum, frame):
    raise Terminated() if signum == signal.SIGTERM else KeyboardInterrupt()


def sigterm_as_interrupt():
    """For a command: SIGTERM outside training raises ``Terminated`` as Ctrl-C raises ``KeyboardInterrupt``,
    so both end a run on one path (in the main thread only). Returns the function that puts the previous
    handler back."""
    if threading.current_thread() is not threading.main_thread():
        return lambda: None
    previous = signal.signal(signal.SIGTERM, _interrupt)
    return lambda: signal.signal(signal.SIGTERM, previous)


class StopRequest:
    """Whether a stop was asked for, and by which signal (``signum``; SIGINT for ``request()`` in code)."""

    def __init__(self, log):
        self.log = log
        self.signum: int | None = None

    @property
    def requested(self) -> bool:
        return self.signum is not None

    def request(self, signum: int = signal.SIGINT) -> None:
        """Stop after the current step, saving a checkpoint (what the first Ctrl-C or SIGTERM does)."""
        self.signum = int(signum)

    def install(self):
        """Routes SIGINT and SIGTERM here while training runs (in the main thread only); returns the function
        that puts the previous handlers back."""
        if threading.current_thread() is not threading.main_thread():
            return lambda: None
        previous = {s: signal.getsignal(s) for s in SIGNALS}

        def handler(signum, frame):
            if self.requested:  # the second signal: stop now; the last checkpoint on disk stays intact
                for s in SIGNALS:
                    signal.signal(s, _interrupt)
                _interrupt(signum, frame)
            self.request(signum)
            name = _NAMES.get(signum, f"signal {signum}")
            self.log(f"\nwarpgs: {name}: finishing this step and saving a checkpoint ({name} again to stop at once)")

        for s in SIGNALS:
            signal.signal(s, handler)

        def restore():
            for s, h in previous.items():
                signal.signal(s, h)

        return restore


def exit_code(signum: int | None) -> int:
    """The exit code of a run stopped by ``signum``: 128 + it (130 Ctrl-C, 143 SIGTERM)."""
    return 128 + int(signum if signum is not None else signal.SIGINT)


def interrupt_code(e: KeyboardInterrupt) -> int:
    """The exit code of a run ended by ``e`` (``Terminated``: 143, else 130)."""
    return exit_code(getattr(e, "signum", None))


# A device allocation that failed outside torch's caching allocator: a CUDA call torch makes directly (its context,
# a stream), cuBLAS's workspace (CUBLAS_STATUS_ALLOC_FAILED), Warp's allocator ("Failed to allocate N bytes on
# device 'cuda:0'"). These raise a plain RuntimeError, not torch.OutOfMemoryError, but are the same event: runs
# sharing a GPU left no room (four fern runs of a sweep at 12 runs a GPU, 2026-11-29).
OUT_OF_MEMORY = re.compile(r"out of memory|OutOfMemoryError|cudaErrorMemoryAllocation|CUDA_ERROR_OUT_OF_MEMORY|"
                           r"CUBLAS_STATUS_ALLOC_FAILED|Failed to allocate \d+ bytes on device 'cuda")


def is_out_of_memory(e: BaseException) -> bool:
    """Whether ``e`` says the device ran out of memory (``torch.OutOfMemoryError``, or a ``RuntimeError`` of CUDA,
    cuBLAS or Warp that says so: ``OUT_OF_MEMORY``)."""
    return isinstance(e, RuntimeError) and (type(e).__name__ == "OutOfMemoryError"
                                            or OUT_OF_MEMORY.search(str(e)) is not None)
