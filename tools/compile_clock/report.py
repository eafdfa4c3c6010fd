"""Print what Numba compiled during a test run (tools/compile_clock/sitecustomize.py):
usage: report.py LOG_FOLDER SUITE_SECONDS WORKERS."""

import sys
from pathlib import Path


def main(folder: str, suite_seconds: float, workers: int) -> str:
    rows = [p.read_text().split() for p in Path(folder).glob("*.txt")]
    count = sum(int(r[0]) for r in rows)
    seconds = sum(float(r[1]) for r in rows)
    if not count:
        return (f"tools/test: {suite_seconds / 60:.1f} min; Numba compiled nothing (every kernel came from "
                "its on-disk cache)")
    share = seconds / max(workers, 1)
    return (f"tools/test: {suite_seconds / 60:.1f} min: Numba compiled {count} kernels in {seconds:.0f} s of "
            f"CPU time in {len(rows)} processes (cache misses; about {share / 60:.1f} min of the wall time "
            f"on {workers} worker(s), {100 * min(share / suite_seconds, 1):.0f} %); the rest is running the "
            "tests. A warm cache skips the compiling.")


if __name__ == "__main__":
    print(main(sys.argv[1], float(sys.argv[2]), int(sys.argv[3])))
