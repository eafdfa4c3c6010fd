"""Print what Numba compiled during a test run (tools/compile_clock/sitecustomize.py):
usage: report.py LOG_FOLDER SUITE_SECONDS WORKERS."""

import collections
import sys
from pathlib import Path


def main(folder: str, suite_seconds: float, workers: int) -> str:
    files = list(Path(folder).glob("*.txt"))
    by_name = collections.defaultdict(lambda: [0, 0.0])
    for path in files:
        for line in path.read_text().splitlines():
            seconds, name = line.split()[:2]
            by_name[name][0] += 1
            by_name[name][1] += float(seconds)
    head = f"tools/test: {suite_seconds / 60:.1f} min"
    if not by_name:
        return f"{head}; Numba compiled nothing (every kernel came from its on-disk cache)"
    count = sum(c for c, _ in by_name.values())
    seconds = sum(s for _, s in by_name.values())
    share = seconds / max(workers, 1)
    top = sorted(by_name.items(), key=lambda item: -item[1][1])[:3]
    most = ", ".join(f"{name} {c}x {s:.0f} s" for name, (c, s) in top)
    return (f"{head}, of which Numba compiling about {share / 60:.1f} min "
            f"({100 * min(share / suite_seconds, 1):.0f} % on {workers} worker(s)): {count} kernels compiled in "
            f"{seconds:.0f} s of CPU time by {len(files)} processes (cache misses; most: {most}); a warm cache "
            "skips that")


if __name__ == "__main__":
    print(main(sys.argv[1], float(sys.argv[2]), int(sys.argv[3])))
