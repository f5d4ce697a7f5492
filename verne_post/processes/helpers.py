"""Helper processes of :func:`verne_post.pipeline.post`: on a machine with more than one core, a
long program's planning (stage 6) and verification (stage 7) run beside the main process, which
meanwhile solves, checks and writes the next part. And :class:`Pool`: independent calls side by
side (placement's room: the full checks of different directions).

A helper is a forked process that runs what it is handed in the order it was handed (a process
pool of one worker), so the verifier keeps where its reading of the program stands from one part
to the next. The results are the bits the main process would have computed: the same code on
the same numbers (tests/test_helpers.py).
"""

from __future__ import annotations

import multiprocessing
import signal
import time
from collections.abc import Callable
from concurrent.futures import Future, ProcessPoolExecutor
from concurrent.futures.process import BrokenProcessPool
from typing import Any, TypeVar

from ..errors import HelperError
from ..machine import Machine
from ..verify.verifier import Reference, Verification, Verifier

T = TypeVar("T")


def _start(then: Callable[..., None] | None, args: tuple) -> None:
    # Ctrl-C is the main process's to handle (it stops the helpers): no traceback from a helper.
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    if then is not None:
        then(*args)


def available(workers: int) -> bool:
    """Whether to post with helpers: more than one worker, and processes that can be forked."""
    return workers > 1 and "fork" in multiprocessing.get_all_start_methods()


def outcome(future: Future[T]) -> T:
    """The result of a call handed to a helper (waits for it); raises what the call raised, or
    :class:`~verne_post.errors.HelperError` when the helper died before it was done."""
    try:
        return future.result()
    except BrokenProcessPool:
        raise _died() from None


def _died() -> HelperError:
    return HelperError("a helper process stopped before its work was done (killed, or out of memory?); "
                       "--workers 1 posts in one process")


def _started() -> None:
    """Nothing: the first call a helper gets, so that it starts at once."""


def _forked(workers: int, initializer: Callable[..., None] | None, initargs: tuple) -> ProcessPoolExecutor:
    """Up to ``workers`` forked processes, ``initializer(*initargs)`` called in each as it starts
    (with fork nothing is pickled for that), Ctrl-C left to the main process."""
    return ProcessPoolExecutor(max_workers=workers, mp_context=multiprocessing.get_context("fork"),
                               initializer=_start, initargs=(initializer, initargs))


def _submit(pool: ProcessPoolExecutor, function: Callable[..., T], *args: Any) -> Future[T]:
    try:
        return pool.submit(function, *args)
    except BrokenProcessPool:
        raise _died() from None


class Helper:
    """A forked process that runs the calls handed to it in turn; ``initializer(*initargs)`` is
    called as it starts (with fork nothing is pickled for that)."""

    def __init__(self, initializer: Callable[..., None] | None = None, initargs: tuple = ()) -> None:
        self._pool = _forked(1, initializer, initargs)
        self._pool.submit(_started)

    def submit(self, function: Callable[..., T], *args: Any) -> Future[T]:
        """Run ``function(*args)`` there, after everything handed over before."""
        return _submit(self._pool, function, *args)

    def close(self) -> None:
        """Stop, once what is under way is done: what has not started is dropped (a failed run
        needs none of it). Waiting matters: a pool left running into the interpreter's exit
        can fail there with an OSError printed to stderr."""
        self._pool.shutdown(wait=True, cancel_futures=True)


_context: Any = None  # what the processes of a Pool share (inherited at the fork, not pickled)


def _set_context(context: Any) -> None:
    global _context
    _context = context


def _in_context(function: Callable[..., T], args: tuple) -> T:
    return function(_context, *args)


class Pool:
    """Up to ``workers`` forked processes that run calls ``function(context, *args)`` side by side:
    ``context`` is inherited at the fork (not pickled), only the arguments and results travel.
    With one worker, no fork, or a single call, the calls run in this process, in turn: the same
    code on the same numbers either way. ``function`` must be a module's (it is pickled by name)."""

    def __init__(self, context: Any, workers: int) -> None:
        self._context = context
        self._pool = _forked(workers, _set_context, (context,)) if available(workers) else None

    def map(self, function: Callable[..., T], calls: list[tuple]) -> list[T]:
        """``function(context, *args)`` for each ``args`` of ``calls``, the results in that order."""
        if self._pool is None or len(calls) < 2:
            return [function(self._context, *args) for args in calls]
        futures = [_submit(self._pool, _in_context, function, args) for args in calls]
        return [outcome(future) for future in futures]

    def close(self) -> None:
        if self._pool is not None:
            self._pool.shutdown(wait=True, cancel_futures=True)


_machine: Machine | None = None  # the machine of the verifier helper it lives in (inherited, not pickled)
_verifier: Verifier | None = None  # its verifier


def _keep(machine: Machine) -> None:
    global _machine
    _machine = machine


def _new_verifier(settings: dict[str, Any]) -> None:
    global _verifier
    assert _machine is not None
    _verifier = Verifier(_machine, **settings)


def _read(text: str, reference: Reference | None, final: bool) -> float:
    assert _verifier is not None
    start = time.perf_counter()
    _verifier.read(text, reference, final)
    return time.perf_counter() - start


def _result() -> Verification:
    assert _verifier is not None
    return _verifier.result()


class VerifierProcess:
    """A :class:`~verne_post.verify.verifier.Verifier` in a helper process, started before its settings
    are known (the work offset comes after placement): :meth:`start` gives them, :meth:`read`
    hands a part over and returns at once, :meth:`result` waits for every part (and raises
    what a reading raised)."""

    def __init__(self, machine: Machine) -> None:
        self._helper = Helper(_keep, (machine,))
        self._started: Future[None] | None = None
        self._reads: list[Future[float]] = []
        self.seconds = 0.0  # spent verifying, once :meth:`result` has been called

    def start(self, **settings: Any) -> VerifierProcess:
        """The settings of :class:`~verne_post.verify.verifier.Verifier` (source, tolerances, work offset)."""
        self._started = self._helper.submit(_new_verifier, settings)
        return self

    def read(self, text: str, reference: Reference | None = None, final: bool = False) -> None:
        self._reads.append(self._helper.submit(_read, text, reference, final))

    def result(self) -> Verification:
        assert self._started is not None, "start() gives the settings first"
        outcome(self._started)
        self.seconds = sum(outcome(read) for read in self._reads)
        return outcome(self._helper.submit(_result))

    def close(self) -> None:
        self._helper.close()
