"""Runs skinrs calls in a child process, so that a segfault, an abort or a hang fails a test
instead of killing pytest.

One worker process is reused across calls (starting Python and importing skinrs per call would
cost ~0.5 s); when it dies or exceeds the per-call timeout, the call is reported as a crash or a
hang and a fresh worker is started for the next call.

A call names its target as ``"module:function"`` (resolved in the worker) and returns
``Outcome``: the value (pickled back), or the exception's type, base classes and message.
"""

from __future__ import annotations

import importlib
import multiprocessing as mp
import os
from dataclasses import dataclass, field


@dataclass
class Outcome:
    value: object = None
    error: str | None = None  # exception type name
    bases: tuple = field(default_factory=tuple)  # names along its MRO
    message: str = ""

    def raised(self, *names: str) -> bool:
        return self.error is not None and any(n in self.bases for n in names)


class Crash(AssertionError):
    """The worker died (segfault, abort, out-of-memory kill) or hung."""


def _resolve(target: str):
    mod, _, name = target.partition(":")
    obj = importlib.import_module(mod)
    for part in name.split("."):
        obj = getattr(obj, part)
    return obj


def _serve(conn) -> None:
    # The worker's stdout/stderr belong to C libraries (TetGen prints); results go through conn.
    while True:
        try:
            target, args, kwargs = conn.recv()
        except EOFError:
            return
        try:
            value = _resolve(target)(*args, **kwargs)
            out = Outcome(value=value)
        except BaseException as e:  # noqa: BLE001 - every exception is reported to the parent
            out = Outcome(
                error=type(e).__name__,
                bases=tuple(c.__name__ for c in type(e).__mro__),
                message=str(e),
            )
        try:
            conn.send(out)
        except Exception as e:  # noqa: BLE001 - an unpicklable result
            conn.send(
                Outcome(error="UnpicklableResult", bases=("UnpicklableResult",), message=str(e))
            )


class Sandbox:
    """A reusable worker process; ``call`` raises ``Crash`` when it dies or exceeds ``timeout``."""

    def __init__(self, timeout: float = 30.0):
        self.timeout = timeout
        self._ctx = mp.get_context("spawn")
        self._proc = None
        self._conn = None
        self.calls = 0

    def _start(self) -> None:
        parent, child = self._ctx.Pipe()
        env_threads = os.environ.get("RAYON_NUM_THREADS")
        self._proc = self._ctx.Process(target=_serve, args=(child,), daemon=True)
        self._proc.start()
        child.close()
        self._conn = parent
        del env_threads

    def close(self) -> None:
        if self._proc is not None:
            self._proc.kill()
            self._proc.join(5)
            self._conn.close()
        self._proc = self._conn = None

    def call(self, target: str, *args, **kwargs) -> Outcome:
        if self._proc is None or not self._proc.is_alive():
            self._start()
        self.calls += 1
        self._conn.send((target, args, kwargs))
        if not self._conn.poll(self.timeout):
            self.close()
            raise Crash(f"{target} hung: no answer within {self.timeout:g} s")
        try:
            return self._conn.recv()
        except (EOFError, ConnectionError, OSError):
            self._proc.join(5)
            code = self._proc.exitcode
            self.close()
            raise Crash(f"{target} killed the process (exit code {code})") from None
