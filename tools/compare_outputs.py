"""Compare two runs' outputs bit for bit: every history series and every dataset of the
last snapshot (in global-id order). Used to check that a change of the code leaves the
particle states of the scenes unchanged:

    python tools/compare_outputs.py OUT_A OUT_B        # exit 0 if identical, 1 if not

The snapshot field "rank" (the owner rank) is compared only when both runs used the same
number of ranks (the same largest rank).
"""

from __future__ import annotations

import os
import sys

import h5py
import numpy as np


def differences(a: str, b: str) -> list:
    """What differs between the runs in directories a and b."""
    out = []
    with h5py.File(os.path.join(a, "history.h5"), "r") as fa, h5py.File(os.path.join(b, "history.h5"), "r") as fb:
        for name in sorted(set(fa) | set(fb)):
            if name not in fa or name not in fb:
                out.append(f"history series {name} only in {'b' if name in fb else 'a'}")
            elif not np.array_equal(fa[name][()], fb[name][()]):
                out.append(f"history series {name} differs")
    with h5py.File(os.path.join(a, "snapshots.h5"), "r") as fa, h5py.File(os.path.join(b, "snapshots.h5"), "r") as fb:
        la = sorted(k for k in fa if k.startswith("step_"))
        lb = sorted(k for k in fb if k.startswith("step_"))
        if la[-1:] != lb[-1:]:
            return out + [f"last snapshots differ: {la[-1:]} and {lb[-1:]}"]
        ga, gb = fa[la[-1]], fb[lb[-1]]
        same_ranks = "rank" in ga and "rank" in gb and ga["rank"][()].max() == gb["rank"][()].max()
        for name in sorted(set(ga) | set(gb)):
            if name == "rank" and not same_ranks:
                continue
            if name not in ga or name not in gb:
                out.append(f"snapshot field {name} only in {'b' if name in gb else 'a'}")
            elif not np.array_equal(ga[name][()], gb[name][()]):
                out.append(f"snapshot field {name} differs (max |a - b| = "
                           f"{np.abs(ga[name][()] - gb[name][()]).max():.3g})")
    return out


def main(argv: list) -> int:
    if len(argv) != 2:
        print(__doc__.strip(), file=sys.stderr)
        return 2
    found = differences(*argv)
    for line in found:
        print(line)
    print("identical" if not found else f"{len(found)} difference(s)")
    return 1 if found else 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
