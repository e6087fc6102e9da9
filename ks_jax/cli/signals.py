"""Ctrl-C and kill during a command: unwound as exceptions, so that an earlier output stays as it was and a
sweep keeps the points it finished in a file of their own."""

from __future__ import annotations

import signal

_SIGNALLED = []  # signals received by the command, kept in case a library swallows the exception


def stopped(signum, frame):
    """SIGINT (Ctrl-C) and SIGTERM (a kill): KeyboardInterrupt and SystemExit(128 + signum). The signal is
    also kept, and ``raise_if_stopped`` raises again where the command checks: a library that catches the
    exception raised inside it cannot make the command carry on as if nothing had happened."""
    _SIGNALLED.append(signum)
    if signum == signal.SIGINT:
        raise KeyboardInterrupt
    raise SystemExit(128 + signum)


def raise_if_stopped():
    """Raise again for a signal that ``stopped`` received (nothing if none did)."""
    if _SIGNALLED:
        stopped(_SIGNALLED[-1], None)


def install():
    """Handle SIGTERM and SIGINT with ``stopped``."""
    signal.signal(signal.SIGTERM, stopped)
    signal.signal(signal.SIGINT, stopped)
