"""Ctrl-C during `fit`: the first SIGINT asks the run to stop at the next step boundary, where it
writes a checkpoint and raises `Interrupted`; a second one raises `KeyboardInterrupt` at once
(nothing more is saved). Outside the main thread (where Python delivers signals) nothing
changes."""

from __future__ import annotations

import os
import signal
import threading


class Interrupted(KeyboardInterrupt):
    """A run stopped by Ctrl-C at a step boundary, its checkpoint written: `step` steps of
    `steps` done, the run in folder `out` (resume it with resume=True, `fit --resume`)."""

    def __init__(self, step: int, steps: int, out: str):
        super().__init__(f"interrupted after step {step} of {steps}; the checkpoint in {out} "
                         f"resumes it")
        self.step, self.steps, self.out = step, steps, out


class StopRequest:
    """`with StopRequest() as stop:` ... `stop.requested` turns true at the first SIGINT
    (module docstring); the previous handler is back after the block."""

    def __init__(self):
        self.requested, self._previous = False, None

    def _handle(self, signum, frame) -> None:
        if self.requested:
            raise KeyboardInterrupt
        self.requested = True
        os.write(2, b"\nCtrl-C: stopping after this step and writing a checkpoint "
                    b"(Ctrl-C again stops at once, without one)\n")

    def __enter__(self):
        if threading.current_thread() is threading.main_thread():
            self._previous = signal.signal(signal.SIGINT, self._handle)
        return self

    def __exit__(self, *exc):
        if self._previous is not None:
            signal.signal(signal.SIGINT, self._previous)
            self._previous = None
