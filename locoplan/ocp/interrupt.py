"""IPOPT solves that Ctrl-C stops (every optimal-control transcription calls its solver through
:func:`solve_nlp`).

No CasADi here: the solver object comes in built.
"""

from __future__ import annotations

import signal
import threading


def solve_nlp(solver, **args) -> dict:
    """``solver(**args)``, stopped by Ctrl-C: raises ``KeyboardInterrupt`` when one came during the solve.

    CasADi checks for Python's signals in IPOPT's intermediate callback, which runs every iteration; a
    ``KeyboardInterrupt`` raised there stops IPOPT (status ``NonIpopt_Exception_Thrown``), but CasADi keeps
    the exception to itself and returns as from a failed solve, so a caller would go on (try another start,
    another mesh) and finish its work. Here the interrupt is also noted, and raised again once IPOPT is back:
    an interrupted solve stops within an iteration. (Python lets only its main thread set a signal handler;
    elsewhere the solve runs as it is.)"""
    if threading.current_thread() is not threading.main_thread() or signal.getsignal(signal.SIGINT) is not signal.default_int_handler:
        return solver(**args)
    hit = []

    def interrupted(signum, frame):
        hit.append(signum)
        raise KeyboardInterrupt

    signal.signal(signal.SIGINT, interrupted)
    try:
        out = solver(**args)
    finally:
        signal.signal(signal.SIGINT, signal.default_int_handler)
    if hit:
        raise KeyboardInterrupt
    return out
