"""The `parsph` command: run, check, preview, keys, info, plot.

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
    r.add_argument("--restart", metavar="CHECKPOINT",
                   help="continue from a checkpoint file, or 'latest' (newest valid one in OUT/checkpoints)")
    r.add_argument("--quiet", action="store_true", help="no progress lines")
    r.add_argument("--debug", action="store_true",
                   help="check at every history row that no particle is lost or duplicated")
    r.add_argument("--profile", action="store_true",
                   help="report per stage the flops and bytes of a step against the core's peak and memory "
                        "bandwidth, pairs and bytes per particle")
    c = sub.add_parser("check", help="validate a scene and print it resolved, with defaults")
    c.add_argument("scene")
    c.add_argument("--set", action="append", default=[], metavar="KEY=VALUE")
    pv = sub.add_parser("preview", help="write the scene's particles and obstacles before any step, with a "
                                        "picture and a summary (under mpirun as run)")
    pv.add_argument("scene", help="scene file (TOML)")
    pv.add_argument("--out", help="output directory (default results/NAME/preview)")
    pv.add_argument("--set", action="append", default=[], metavar="KEY=VALUE", help="override a scene key, as run")
    pv.add_argument("--overwrite", action="store_true", help="replace a previous preview in --out")
    k = sub.add_parser("keys", help="print the scene keys: type, unit, default, allowed values and meaning")
    k.add_argument("section", nargs="?",
                   help="only this section and those under it: time, bc, geometry.parts.box, material.johnson_cook")
    k.add_argument("--markdown", action="store_true", help="as Markdown (docs/scene-keys.md is the whole of it)")
    sub.add_parser("info", help="print the environment: versions, ranks, parallel HDF5, threads")
    pl = sub.add_parser("plot", help="plot history series or snapshot fields to PNG")
    pl.add_argument("file", help="a run's history.h5 or snapshots.h5 (told apart by what they hold)")
    pl.add_argument("names", nargs="*", help="history series (default: energies) or one snapshot field (default: J)")
    pl.add_argument("--frames", type=int, help="snapshots to draw side by side (default 4; 1: the last)")
    pl.add_argument("--limits", type=float, nargs=2, metavar=("LOW", "HIGH"),
                    help="colour scale of a snapshot field (default: its range over the frames)")
    pl.add_argument("--output", "-o", help=".png file (default next to the input file)")
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


def main(argv=None) -> int:
    args = _parser().parse_args(argv)
    from parsph.parallel.runtime import fail_all, say

    try:
        if args.command == "run":
            from parsph.parallel.runtime import warn_if_oversubscribed

            warn_if_oversubscribed()  # before the imports and the set-up, which crowded ranks slow down
            from parsph.run import run

            return run(args.scene, args.out, args.set, args.overwrite, args.quiet, args.restart, args.debug,
                       args.profile)
        elif args.command == "check":
            import json

            from parsph import config
            from parsph.parallel.runtime import collective

            with collective():
                scene = config.load(args.scene, args.set)
            say(json.dumps(scene.as_dict(), indent=2))
        elif args.command == "preview":
            from parsph.preview import preview

            return preview(args.scene, args.out, args.set, args.overwrite)
        elif args.command == "keys":
            from parsph import keyref
            from parsph.parallel.runtime import collective

            with collective():
                reference = (keyref.markdown if args.markdown else keyref.text)(args.section)
            say(reference, end="")
        elif args.command == "info":
            info()
        elif args.command == "plot":
            from parsph.io import plots
            from parsph.parallel.runtime import COMM, collective

            with collective():  # rank 0 plots; the others end as it does
                written = plots.plot(args.file, args.names, args.output, args.frames, args.limits) \
                    if COMM.rank == 0 else None
            say(written)
    except KeyboardInterrupt:
        return 130
    except BrokenPipeError:  # the reader of the output (`| head`) has stopped reading
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        from parsph.errors import ParsphError
        from parsph.parallel.runtime import COMM

        return 141 if COMM.size == 1 else fail_all(ParsphError("its standard output was closed"))
    except BaseException as exc:  # noqa: BLE001 - every failure ends all ranks
        if isinstance(exc, SystemExit):
            raise
        return fail_all(exc)
    return 0
