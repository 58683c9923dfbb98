"""Stopping a long run cleanly: SIGTERM or Ctrl-C during ``learn`` writes a checkpoint at the next env step.

A Sawyer run or directed collection keeps a checkpoint every 10,000 transitions (``eval.resume``,
``eval.pretraining``), 20 to 30 minutes of one core apart. A process killed between two of them loses that work.
Inside :func:`stop_at_next_step`, SIGTERM (what ``kill``, a batch scheduler's preemption or a session's end sends)
and Ctrl-C (SIGINT) do not end the process: they set a flag. The run's checkpoint callback
(``eval.resume.ResumeCheckpoint``) sees it after the current env step (a step ends within a second; an evaluation
in progress is finished first), writes the same checkpoint the run writes after an evaluation, and stops ``learn``.
The job then ends with status ``"stopped"`` (:class:`RunStopped`), and the same command, run again, resumes from
that step. A second signal stops the process at once, as without this module, leaving the last checkpoint written.

A sweep (``LocalExecutor.map``, ``eval.paper.runner.run_parts``) runs inside :func:`sweep_stop`: a stop request
received anywhere in it (inside a run's ``learn``, during its final evaluation, between two runs) outlives the run
it arrived in. The run in progress finishes or writes its checkpoint, no further run starts, and a later run's
block starts with its flag already set, so that a second signal is taken as the second, not as a new first.

Outside these blocks (building envs, offline training, figures) the signals keep their usual
effect, except in the workers of ``LocalExecutor``'s pool, which remember them (:func:`install_worker_handlers`):
there the job in progress finishes and no other starts. Handlers can be set only in a process's main thread;
elsewhere (a Ray worker's task thread) the block does nothing and the signals keep their usual effect too.
"""

from __future__ import annotations

import contextlib
import os
import signal
import sys
import threading
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from typing import Any

STOP_SIGNALS: tuple[signal.Signals, ...] = (signal.SIGTERM, signal.SIGINT)
"""The signals that ask for a checkpoint and a stop."""


class RunStopped(Exception):
    """A run (or a directed collection) stopped at a signal after writing its checkpoint; run it again to resume."""


@dataclass
class StopFlag:
    """Set by the handlers of :func:`stop_at_next_step` when a stop is asked for.

    :param signal_name: the signal received first ("SIGTERM", "SIGINT"), None while none was.
    """

    signal_name: str | None = None

    @property
    def requested(self) -> bool:
        """Whether a stop was asked for."""
        return self.signal_name is not None


_received: list[str] = []
"""The signals this process's handlers received, first first."""

_worker = False
"""Whether this process is a pool worker (:func:`install_worker_handlers`)."""

_sweeps: list[StopFlag] = []
"""The flags of the :func:`sweep_stop` blocks open in this process, outermost first: every stop signal sets them."""


def _handler(flag: StopFlag, on_request: Callable[[str], None] | None, message: str | None) -> Callable[[int, Any], None]:
    """A signal handler that sets ``flag`` on the first signal; a second one stops the process at once.

    At once means as without the handler: a second SIGINT raises ``KeyboardInterrupt``, a second SIGTERM ends the
    process by SIGTERM (``Process.terminate`` twice, ``kill`` twice).
    """

    def handler(signum: int, frame: Any) -> None:
        name = signal.Signals(signum).name
        _received.append(name)
        second = flag.requested
        for sweep in _sweeps:  # the request outlives the run it arrived in
            if not sweep.requested:
                sweep.signal_name = name
        if second:
            if signum == signal.SIGINT:
                raise KeyboardInterrupt
            signal.signal(signum, signal.SIG_DFL)
            os.kill(os.getpid(), signum)
            return
        flag.signal_name = name
        if message:
            print(f"ebm-eval: {name} received: {message}", file=sys.stderr, flush=True)
        if on_request is not None:
            on_request(name)

    return handler


def stop_received() -> str | None:
    """The first stop signal this process's handlers received (None: none): a pool worker starts no job after one."""
    return _received[0] if _received else None


def install_worker_handlers() -> None:
    """For a pool worker, at its start: a first SIGTERM or SIGINT is remembered rather than ending the process.

    The job in progress goes on (inside ``learn`` it writes its checkpoint at the next step and stops;
    :func:`stop_at_next_step` sees a signal received before ``learn`` started), and the worker starts no further
    job (``stop_received``). A second signal stops it at once.
    """
    global _worker
    _worker = True
    handler = _handler(StopFlag(), None, None)
    for signum in STOP_SIGNALS:
        signal.signal(signum, handler)


@contextlib.contextmanager
def stop_at_next_step(on_request: Callable[[str], None] | None = None, quiet: bool = False) -> Iterator[StopFlag]:
    """Within the block, a first SIGTERM or SIGINT sets the yielded flag instead of ending the process.

    A second signal stops the process at once, as it would without the block (``KeyboardInterrupt`` for SIGINT,
    death by SIGTERM). The handlers in place before the block are put back at its end. In a thread other than the
    main one, no handler is set and the flag stays unset. In a pool worker that already received a stop signal,
    the flag is set from the start.

    :param on_request: called once, from the handler, with the signal's name ("SIGTERM") when the first signal
        arrives (e.g. to pass it on to worker processes).
    :param quiet: print nothing when a signal arrives (by default one line on stderr says what happens).
    :return: the flag (a context manager yielding it).
    """
    flag = StopFlag(signal_name=stop_received() if _worker else _sweep_request())
    if threading.current_thread() is not threading.main_thread():
        yield flag
        return
    message = (
        None
        if quiet
        else (
            "writing a checkpoint after the current step, then stopping (run the same command again to resume; "
            "a second signal stops at once)"
        )
    )
    handler = _handler(flag, on_request, message)
    previous = {signum: signal.signal(signum, handler) for signum in STOP_SIGNALS}
    try:
        yield flag
    finally:
        for signum, old in previous.items():
            signal.signal(signum, old)


def _sweep_request() -> str | None:
    """The signal that stopped an open sweep of this process (None: none did, or no sweep is open)."""
    return next((sweep.signal_name for sweep in _sweeps if sweep.requested), None)


@contextlib.contextmanager
def sweep_stop(on_request: Callable[[str], None] | None = None) -> Iterator[StopFlag]:
    """A sweep of runs: a stop signal received anywhere within the block sets the yielded flag, for the whole block.

    Inside a run's :func:`stop_at_next_step` block the run's handler takes the signal and sets this flag too;
    between runs (and in a run's final evaluation, outside ``learn``) this block's own handler takes it instead of
    ending the process. Either way the sweep starts no further run once the flag is set, and a run started after it
    starts with its own flag set (a second signal then stops at once). Blocks nest; the handlers in place before the
    block are put back at its end.

    :param on_request: called once, from the handler, with the signal's name when the first signal arrives
        between runs (e.g. to pass it on to worker processes).
    :return: the flag (a context manager yielding it).
    """
    with stop_at_next_step(on_request=on_request, quiet=True) as flag:
        _sweeps.append(flag)
        try:
            yield flag
        finally:
            _sweeps.remove(flag)


def raise_if_stopped(flag: StopFlag, done: int, total: int, what: str, where: object) -> None:
    """Raise :class:`RunStopped` when ``learn`` returned early because of ``flag``.

    :param flag: the flag of :func:`stop_at_next_step`.
    :param done: transitions consumed.
    :param total: the budget.
    :param what: the run, in words ("run ...", "directed collection ...").
    :param where: the checkpoint folder.
    :raises RunStopped: when a stop was asked for before the budget was consumed.
    """
    if flag.requested and done < total:
        raise RunStopped(
            f"{what} stopped by {flag.signal_name} at {done:,}/{total:,} transitions; its checkpoint is in {where}/: "
            "run the same command again to resume"
        )
