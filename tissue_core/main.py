"""``python -m PACKAGE``, kept to what is already loaded, so that Ctrl-C at any moment of the
start ends with one line and exit status 130 (see :func:`tissue_core.cli.run_module`)."""

import os
import sys


def run(package: str) -> None:
    """Run ``PACKAGE.cli.main()`` as the process and exit with its status."""
    try:
        from tissue_core.cli import run_module
    except KeyboardInterrupt:
        print(f"{package}: interrupted; no output written", file=sys.stderr, flush=True)
        os._exit(130)
    run_module(f"{package}.cli")
