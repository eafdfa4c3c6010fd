"""The `parsph` command: run, check, info, plot.

Bad input ends with a one-line message and exit code 2 on every rank; any other failure on
any rank ends all ranks (see parallel.runtime).
"""

from __future__ import annotations

import argparse
import os
import sys

from parsph import __version__


class _Parser(argparse.ArgumentParser):
    def error(self, message):  # usage errors are bad input: exit code 2, printed once
        from parsph.parallel.runtime import COMM

        if COMM.rank == 0:
            self.print_usage(sys.stderr)
            print(f"parsph: error: {message}", file=sys.stderr, flush=True)
        raise SystemExit(2)


def _parser() -> argparse.ArgumentParser:
    p = _Parser(prog="parsph", description="MPI-parallel corrected SPH for solid mechanics.")
    p.add_argument("--version", action="version", version=f"parsph {__version__}")
    sub = p.add_subparsers(dest="command", required=True, parser_class=_Parser)
    r = sub.add_parser("run", help="run a scene (under mpirun for several ranks)")
    r.add_argument("scene", help="scene file (TOML)")
    r.add_argument("--out", help="output directory (default results/NAME)")
    r.add_argument("--set", action="append", default=[], metavar="KEY=VALUE",
                   help="override a scene key, e.g. --set time.end=1e-3 --set bc.0.ramp=0.1")
    r.add_argument("--overwrite", action="store_true", help="replace a previous run in --out")
    r.add_argument("--quiet", action="store_true", help="no progress lines")
    c = sub.add_parser("check", help="validate a scene and print it resolved, with defaults")
    c.add_argument("scene")
    c.add_argument("--set", action="append", default=[], metavar="KEY=VALUE")
    sub.add_parser("info", help="print the environment: versions, ranks, parallel HDF5, threads")
    pl = sub.add_parser("plot", help="plot history series to PNG")
    pl.add_argument("history", help="OUT/history.h5")
    pl.add_argument("names", nargs="*", help="series to plot (default: energies)")
    pl.add_argument("--output", "-o", help="PNG file (default next to the history file)")
    return p


def info() -> None:
    import h5py
    import mpi4py
    import numba
    import numpy
    import scipy
    from mpi4py import MPI

    from parsph.parallel.runtime import COMM

    threads = COMM.gather(numba.get_num_threads(), root=0)
    if COMM.rank != 0:
        return
    try:
        layer = numba.threading_layer()
    except ValueError:
        layer = "not initialised (no parallel kernel run yet)"
    lib = MPI.Get_library_version().strip().splitlines()[0]
    rows = [
        ("parsph", __version__), ("python", sys.version.split()[0]), ("numpy", numpy.__version__),
        ("scipy", scipy.__version__), ("numba", numba.__version__), ("mpi4py", mpi4py.__version__),
        ("h5py", h5py.__version__), ("HDF5", h5py.version.hdf5_version),
        ("MPI library", lib), ("MPI ranks", str(COMM.size)),
        ("parallel HDF5", "yes" if h5py.get_config().mpi else "no (output is written through rank 0)"),
        ("numba threading layer", layer),
        ("numba threads per rank", ", ".join(map(str, threads))),
    ]
    width = max(len(k) for k, _ in rows)
    for k, v in rows:
        print(f"{k:<{width}}  {v}")


def plot(history: str, names: list, output: str | None) -> None:
    from parsph.errors import InputError
    from parsph.io.history import read_history

    try:
        import matplotlib
    except ImportError:
        raise InputError("parsph plot needs matplotlib: pip install matplotlib") from None
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    if not os.path.exists(history):
        raise InputError(f"history file not found: {history}")
    data = read_history(history)
    names = names or [n for n in ("kinetic_energy", "strain_energy", "hourglass_energy", "total_energy")
                      if n in data]
    missing = [n for n in names if n not in data]
    if missing:
        raise InputError(f"no series {missing} in {history}; it has: {', '.join(sorted(data))}")
    fig, ax = plt.subplots(figsize=(7, 4.5))
    for n in names:
        ax.plot(data["time"], data[n], label=n)
    ax.set_xlabel("time [s]")
    ax.legend()
    ax.grid(alpha=0.3)
    output = output or os.path.splitext(history)[0] + "_" + "_".join(names)[:80] + ".png"
    fig.tight_layout()
    fig.savefig(output, dpi=120)
    print(output)


def main(argv=None) -> int:
    args = _parser().parse_args(argv)
    from parsph.parallel.runtime import fail_all, say

    try:
        if args.command == "run":
            from parsph.run import run

            run(args.scene, args.out, args.set, args.overwrite, args.quiet)
        elif args.command == "check":
            import json

            from parsph import config
            from parsph.parallel.runtime import collective

            with collective():
                scene = config.load(args.scene, args.set)
            say(json.dumps(scene, indent=2))
        elif args.command == "info":
            info()
        elif args.command == "plot":
            plot(args.history, args.names, args.output)
    except KeyboardInterrupt:
        return 130
    except BaseException as exc:  # noqa: BLE001 - every failure ends all ranks
        if isinstance(exc, SystemExit):
            raise
        return fail_all(exc)
    return 0
