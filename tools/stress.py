#!/usr/bin/env python3
"""Run the full stress suite (tests/stress/cases.py) on every backend and print a markdown table.

    python tools/stress.py [--quick] [--backend numpy --backend opencl] [--json PATH]

Exit code 1 when a row does not have its required outcome.
"""
from __future__ import annotations

import argparse
import json
import sys
import time
from dataclasses import asdict
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from tests.stress.cases import CASES  # noqa: E402
from tests.stress.test_stress import available_backends  # noqa: E402


def table(rows) -> str:
    lines = ["| case | backend | dtype | iterations | outcome | max abs value | NaN count | pass |",
             "|---|---|---|---:|---|---:|---:|---|"]
    for r in rows:
        lines.append(f"| {r.case} | {r.backend} | {r.dtype} | {r.iterations} | {r.outcome} | {r.max_abs:.3g} "
                     f"| {r.nan_count} | {'yes' if r.passed else '**NO**'} |")
    return "\n".join(lines)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="CI sizes instead of the full ones")
    parser.add_argument("--backend", action="append", help="numpy and/or opencl (default: all available)")
    parser.add_argument("--json", default=None, help="also write the rows as JSON")
    args = parser.parse_args(argv)
    rows, start = [], time.perf_counter()
    for backend in args.backend or available_backends():
        for name, case in CASES.items():
            rows.extend(case(backend, "float32", quick=args.quick))
            print(f"{backend} {name}: done at {time.perf_counter() - start:.0f} s", file=sys.stderr)
    print(table(rows))
    if args.json:
        Path(args.json).write_text(json.dumps([asdict(r) for r in rows], indent=1))
    return 0 if all(r.passed for r in rows) else 1


if __name__ == "__main__":
    sys.exit(main())
