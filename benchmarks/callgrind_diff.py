"""Where two checkouts' instructions per call differ, function by function.

Reads the profiles ``side_by_side.py --instructions --callgrind-out DIR`` keeps
(``callgrind.{old,new}.KIND.CALLS``, a run with few calls and one with many), takes each
function's exclusive instructions per call (many minus few, over the difference of the
calls, so start-up cancels) on each side, and prints the functions whose cost differs
most, largest first::

    .venv/bin/python benchmarks/callgrind_diff.py DIR KIND [--top 30]

Functions are the machine code's (the interpreter's C functions, numba's compiled kernels
when numba compiled them in the process, else all together as code without symbols,
NumPy's loops); Python functions show as the interpreter's time.
"""

from __future__ import annotations

import argparse
import re
import subprocess
from collections import defaultdict
from pathlib import Path

_LINE = re.compile(r"^\s*([\d,]+)\s+\([\s\d.]+%\)\s+(.*)$")


def exclusive(profile: Path) -> dict[str, float]:
    """Return ``{function: exclusive instructions}`` of a callgrind profile (all of them)."""
    out = subprocess.run(
        ["callgrind_annotate", "--threshold=100", "--auto=no", str(profile)],
        capture_output=True,
        text=True,
        check=True,
    ).stdout
    costs: dict[str, float] = defaultdict(float)
    for line in out.splitlines():
        match = _LINE.match(line)
        if match and "PROGRAM TOTALS" not in line:
            name = re.sub(r"'\d+", "", match.group(2))  # recursion depths as one function
            name = re.sub(r"^/tmp/python-build[^/]*/", "", name)
            name = re.sub(r"\S*/\.venv/", ".venv/", name)  # either checkout's environment
            if re.match(r"\?\?\?:0x[0-9a-f]+ \[\?\?\?\]", name):
                name = "(machine code without symbols: numba's kernels loaded from the cache)"
            costs[name] += float(match.group(1).replace(",", ""))
    return costs


def per_call(folder: Path, side: str, kind: str) -> dict[str, float]:
    """Return ``{function: exclusive instructions per call}`` of one side and kind."""
    runs = sorted(
        folder.glob(f"callgrind.{side}.{kind}.*"), key=lambda p: int(p.name.rsplit(".", 1)[1])
    )
    if len(runs) != 2:
        raise SystemExit(f"need two profiles callgrind.{side}.{kind}.CALLS in {folder}")
    (lo, few), (hi, many) = ((int(p.name.rsplit(".", 1)[1]), exclusive(p)) for p in runs)
    return {f: (many.get(f, 0.0) - few.get(f, 0.0)) / (hi - lo) for f in set(few) | set(many)}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("folder", type=Path)
    parser.add_argument("kind")
    parser.add_argument("--top", type=int, default=30)
    args = parser.parse_args()
    old, new = (per_call(args.folder, side, args.kind) for side in ("old", "new"))
    total_old, total_new = sum(old.values()), sum(new.values())
    print(f"{args.kind}: old {total_old:,.0f}  new {total_new:,.0f} instructions per call "
          f"(new/old {total_new / total_old:.3f})")  # fmt: skip
    print(f"{'new - old':>12s} {'old':>12s} {'new':>12s}  function")
    diffs = sorted(set(old) | set(new), key=lambda f: -abs(new.get(f, 0) - old.get(f, 0)))
    for f in diffs[: args.top]:
        o, n = old.get(f, 0.0), new.get(f, 0.0)
        print(f"{n - o:12,.0f} {o:12,.0f} {n:12,.0f}  {f[:150]}")


if __name__ == "__main__":
    main()
