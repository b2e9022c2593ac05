"""``python -m PACKAGE``, kept to what is already loaded, so that Ctrl-C (or SIGTERM, SIGHUP) at
any moment of the start ends with one line and exit status 130 (143, 129) (see
:func:`tissue_core.cli.run_module`)."""

import os
import signal
import sys


def run(package: str) -> None:
    """Run ``PACKAGE.cli.main()`` as the process and exit with its status."""
    # SIGTERM and SIGHUP wait (blocked) until the command runner handles them, a moment from
    # now: by default they would end the process without a word
    held = frozenset()
    if hasattr(signal, "pthread_sigmask"):
        wanted = {getattr(signal, n) for n in ("SIGTERM", "SIGHUP") if hasattr(signal, n)}
        held = frozenset(wanted - signal.pthread_sigmask(signal.SIG_BLOCK, wanted))
    try:
        from tissue_core.cli import run_module
    except KeyboardInterrupt:
        print(f"{package}: interrupted; no output written", file=sys.stderr, flush=True)
        os._exit(130)
    run_module(f"{package}.cli", held=held)
