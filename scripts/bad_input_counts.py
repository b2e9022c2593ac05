"""Run the bad-input matrix and print its counts per command (docs/reliability.md's table).

    python scripts/bad_input_counts.py

Runs every ``tests/*/test_bad_input.py`` with pytest (``test_bad_input[...]``:
refused inputs; ``test_interrupt[...]``: Ctrl-C, SIGTERM or SIGHUP at a chosen
moment of a real process, and the scratch of runs killed outright), reads the
outcome of each case from a JUnit XML report, and prints a Markdown table: per
command, the cases by family and how many passed.  Every passing case has
exited with status 2 and one error line naming the file (or, after a signal,
130, 143 or 129 and one line, with no process of its left running; or, after
a run killed outright, a rerun that removed what it left), printed no
traceback, left its inputs byte-identical and removed nothing that was there
before; a case of the formula family (names a spreadsheet would run) was
accepted instead, with every cell of every CSV it wrote inert; see
tests/badinput.py.  Exits 1 when any case failed.
"""

from __future__ import annotations

import subprocess
import sys
import tempfile
import xml.etree.ElementTree as ET
from collections import Counter, defaultdict
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from tests.badinput import FAMILIES, parse_case_id  # noqa: E402

PACKAGES = ("strain2d", "surface_strain", "stereo", "mpm3d", "sample_data_synth")


def main() -> int:
    files = [
        f"tests/{p}/test_bad_input.py"
        for p in PACKAGES
        if (REPO / "tests" / p / "test_bad_input.py").exists()
    ]
    with tempfile.TemporaryDirectory() as tmp:
        report = Path(tmp) / "report.xml"
        run = subprocess.run(
            [
                sys.executable,
                "-m",
                "pytest",
                "-q",
                "-p",
                "no:cacheprovider",
                "-n",
                "auto",
                f"--junitxml={report}",
                *files,
            ],
            cwd=REPO,
            capture_output=True,
            text=True,
        )
        if not report.exists():
            print(run.stdout[-3000:], run.stderr[-3000:], file=sys.stderr)
            return 1
        cases = ET.parse(report).getroot().iter("testcase")
        outcomes = []
        for case in cases:
            name = case.get("name", "")
            if not name.startswith(("test_bad_input[", "test_interrupt[")):
                continue
            failed = any(child.tag in ("failure", "error") for child in case)
            skipped = any(child.tag == "skipped" for child in case)
            case_id = name[name.index("[") + 1 : -1]
            outcomes.append((case.get("classname", ""), case_id, failed, skipped))
    table: dict[str, Counter] = defaultdict(Counter)
    passed: Counter = Counter()
    failed_ids = []
    for classname, case_id, failed, skipped in outcomes:
        package = next(p for p in PACKAGES if f".{p}." in f".{classname}.")
        command, family, _ = parse_case_id(case_id)
        key = f"{package} {command}"
        if skipped:
            continue
        table[key][family] += 1
        if failed:
            failed_ids.append(f"{classname}::{case_id}")
        else:
            passed[key] += 1
    shown = [f for f in FAMILIES if any(t[f] for t in table.values())]
    print("| command | " + " | ".join(shown) + " | all | pass |")
    print("|---|" + "---:|" * (len(shown) + 2))
    for key in sorted(table, key=lambda k: (PACKAGES.index(k.split()[0]), k)):
        counts = table[key]
        cells = [str(counts[f]) if counts[f] else "" for f in shown]
        total = sum(counts.values())
        print(f"| `{key}` | " + " | ".join(cells) + f" | {total} | {passed[key]} |")
    total = sum(sum(c.values()) for c in table.values())
    print(
        f"\n{total} cases, {sum(passed.values())} passed, {len(failed_ids)} failed: "
        "every passing case exited 2 (130 after Ctrl-C, 143 after SIGTERM, 129 after SIGHUP, "
        "with no process of its left running) with one line and no traceback, left its inputs "
        "byte-identical, removed nothing it did not write, and left no scratch (a rerun after "
        "a run killed outright removed what that run left; formula cases: exited 0 with "
        "every CSV cell inert)."
    )
    for case_id in failed_ids:
        print(f"FAILED {case_id}")
    return 1 if failed_ids else 0


if __name__ == "__main__":
    sys.exit(main())
