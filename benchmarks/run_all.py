"""Run every benchmark script in this folder (``benchmarks/*.py`` but this one) and print what each measured."""

from __future__ import annotations

import argparse
import subprocess
import sys
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent


def scripts(pattern: str | None = None) -> list[Path]:
    found = sorted(p for p in HERE.glob("*.py") if p.name != Path(__file__).name and not p.name.startswith("_"))
    return [p for p in found if pattern is None or pattern in p.stem]


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("-k", dest="pattern", default=None, help="only scripts whose name contains this")
    parser.add_argument("--timeout", type=float, default=1800.0, help="seconds per script, default 1800")
    args = parser.parse_args(argv)
    failed: list[str] = []
    found = scripts(args.pattern)
    if not found:
        print("no benchmark scripts found", file=sys.stderr)
        return 1
    for path in found:
        print(f"== {path.name}", flush=True)
        t0 = time.perf_counter()
        try:
            # Each script in its own interpreter: no shared caches or imports skew another's numbers.
            proc = subprocess.run(
                [sys.executable, str(path)],
                cwd=HERE.parent,
                capture_output=True,
                text=True,
                timeout=args.timeout,
                check=False,
            )
            output, code = proc.stdout + proc.stderr, proc.returncode
        except subprocess.TimeoutExpired:
            output, code = f"timed out after {args.timeout:.0f} s\n", -1
        print(output.rstrip("\n"))
        status = "ok" if code == 0 else f"FAILED (exit {code})"
        print(f"-- {path.name}: {status} in {time.perf_counter() - t0:.1f} s\n", flush=True)
        if code != 0:
            failed.append(path.name)
    if failed:
        print(f"{len(failed)} of {len(found)} benchmark(s) failed: {', '.join(failed)}")
        return 1
    print(f"all {len(found)} benchmark(s) ran")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
