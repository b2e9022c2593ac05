"""A stand-in command line for the batch engine's tests: ``main(argv)`` as the toolkit's commands.

``job NAME --out DIR`` writes a result folder (atomically, with a summary);
``--crash`` ends the process at once (a worker killed; ``--crash-once FILE`` only the
first time), ``--fail`` is an error the
user can fix (one line, exit status 2), ``--bug`` an error nobody expected.
"""

from __future__ import annotations

import os
import time

from tissue_core.cli import CommandLine, run_command
from tissue_core.errors import InputError
from tissue_core.jsonio import write_json
from tissue_core.outputs import atomic_dir


def _job(args) -> int:
    if args.crash:
        os._exit(9)
    if args.crash_once and not os.path.exists(args.crash_once):
        open(args.crash_once, "w").close()
        os._exit(9)
    if args.sleep:
        time.sleep(args.sleep)
    if args.fail:
        raise InputError(f"{args.name}: this input cannot be read")
    if args.bug:
        raise ZeroDivisionError("a defect")
    with atomic_dir(args.out, overwrite=args.overwrite) as tmp:
        # the malloc setting the process started with (glibc reads it once, at the start)
        trim = os.environ.get("MALLOC_TRIM_THRESHOLD_")
        write_json(tmp / "summary.json", {"name": args.name, "input_files": [], "trim": trim})
    return 0


def main(argv=None) -> int:
    cli = CommandLine("batchjobs", "A stand-in command for the batch tests.")
    p = cli.command("job", _job)
    p.add_argument("name")
    p.add_argument("--out", required=True)
    p.add_argument("--crash", action="store_true")
    p.add_argument("--crash-once", metavar="FILE", help="crash unless FILE exists (makes it)")
    p.add_argument("--fail", action="store_true")
    p.add_argument("--bug", action="store_true")
    p.add_argument("--sleep", type=float, default=0.0, help="seconds before the rest")
    p.add_argument("--overwrite", action="store_true")
    return run_command("batchjobs", cli, argv)
