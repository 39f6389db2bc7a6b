"""Issue 10's reliability numbers: every case of the generated hostile corpus (tests/hostile.py) run
alone as ``python -m locoplan ...`` under a 20 s time limit and a 1 GiB address-space cap, two at a
time; prints per class: cases, tracebacks, hangs, peak memory, wrong successes, other misses.

    python benchmarks/hostile_corpus.py            # the table (about 3 minutes on 2 cores)
    python benchmarks/hostile_corpus.py --list     # also every case: exit, seconds, peak memory
    python benchmarks/hostile_corpus.py -k alias   # only cases whose name contains 'alias'
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))
import hostile  # noqa: E402


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--list", action="store_true", help="print every case")
    ap.add_argument("-k", default="", help="only cases whose name contains this")
    ap.add_argument("--jobs", type=int, default=2)
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        cases = [c for c in hostile.build(Path(tmp)) if args.k in c.name]
        hostile.warm_up(Path(tmp))  # the compiled kernels exist before the first case is timed
        t = time.perf_counter()
        with ThreadPoolExecutor(args.jobs) as pool:
            outcomes = list(pool.map(lambda c: hostile.run_case(c, Path(tmp)), cases))
        wall = time.perf_counter() - t
    rows: dict[str, list] = {}
    for o in outcomes:
        rows.setdefault(o.case.cls, []).append(o)
    rows["all"] = outcomes
    head = f"{'class':<9} {'cases':>5} {'tracebacks':>10} {'hangs':>5} {'peak MiB':>8} {'max s':>6} {'wrong successes':>15} {'other misses':>12}"
    print(head)
    print("-" * len(head))
    for cls, os_ in rows.items():
        if cls == "all":
            print("-" * len(head))
        other = sum(1 for o in os_ if o.problems and not (o.traceback or o.hang or o.wrong_success))
        print(f"{cls:<9} {len(os_):>5} {sum(o.traceback for o in os_):>10} {sum(o.hang for o in os_):>5} "
              f"{max(o.peak_rss_bytes for o in os_) / 2**20:>8.0f} {max(o.seconds for o in os_):>6.1f} "
              f"{sum(o.wrong_success for o in os_):>15} {other:>12}")
    print(f"\n{len(outcomes)} cases in {wall:.0f} s ({args.jobs} at a time); limits: {hostile.TIME_LIMIT_S:g} s and "
          f"{hostile.MEMORY_CAP_BYTES / 2**30:g} GiB of address space per case")
    for o in outcomes:
        if args.list or o.problems:
            print(f"{'MISS' if o.problems else 'ok  '} {o.case.name:<34} [{o.case.cls}] exit {o.returncode} "
                  f"(expected {o.case.exit}) {o.seconds:5.1f} s {o.peak_rss_bytes / 2**20:5.0f} MiB"
                  + (f"  {'; '.join(o.problems)}" if o.problems else ""))
    return 1 if any(o.problems for o in outcomes) else 0


if __name__ == "__main__":
    sys.exit(main())
