"""Shared test helpers: running `parsph` on one rank or under mpiexec."""

from __future__ import annotations

import os
import shutil
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
RUNS = ROOT / "runs"

# A copy of runs/bar1d.toml without the comments: 40 particles on the nodes of [0, 1] m.
BAR = """\
[scene]
name = "bar1d"
dimension = 1

[geometry]
area = 1.0e-4
[[geometry.parts]]
shape = "box"
lower = [0.0]
upper = [1.0]
spacing = 0.02564102564102564
placement = "node"

[kernel]
type = "cubic_spline"
support = 1.5

[material]
model = "saint_venant_kirchhoff"
density = 7850.0
youngs_modulus = 200.0e9
poisson_ratio = 0.0

[formulation]
type = "tlsph"
hourglass = 0.0

[time]
end = 3.2e-3
cfl = 0.5

[groups.A]
nearest = [0.0]
[groups.B]
nearest = [1.0]
[groups.right_quarter]
box = { lower = [0.75], upper = [1.0] }

[[initial]]
type = "velocity"
group = "right_quarter"
value = [5.0]

[[bc]]
type = "fixed"
group = "A"

[[probes]]
name = "tip_displacement"
group = "B"
quantity = "displacement"
component = 0

[output]
history_interval = 1.0e-5
"""


def mpiexec() -> str:
    """The launcher of the MPI that mpi4py was built against (MPICH on Debian)."""
    for name in ("mpiexec.mpich", "mpiexec"):
        path = shutil.which(name)
        if path:
            return path
    pytest.skip("no mpiexec on PATH")


# No test may fail because the machine is slow or busy: the only wall-clock bound on a
# subprocess, or on waiting for one, is this ceiling against a real hang (a healthy run of the
# suite's scenes takes seconds, a cold compile under load a minute or two). A test that
# checks promptness measures from the event to the reaction (tests/test_failures.py).
CEILING = 900.0  # seconds


def wait_for(condition, poll: float = 0.1) -> None:
    """Poll `condition()` until it is true (at most CEILING seconds: then the test fails)."""
    deadline = time.monotonic() + CEILING
    while not condition():
        if time.monotonic() > deadline:
            pytest.fail(f"waited {CEILING} s for {condition.__doc__ or condition}")
        time.sleep(poll)


def kill_processes_mentioning(marker: str) -> list:
    """SIGKILL every process whose command line contains `marker`; wait until they are gone.
    (MPICH's launcher puts each rank in a session of its own, so a process group kill misses
    them.)"""
    victims = []
    # newest first: the ranks die before the launcher could end them in an orderly way
    for entry in sorted((e for e in os.listdir("/proc") if e.isdigit()), key=int, reverse=True):
        if int(entry) != os.getpid():
            try:
                with open(f"/proc/{entry}/cmdline", "rb") as fh:
                    if marker.encode() in fh.read():
                        os.kill(int(entry), signal.SIGKILL)
                        victims.append(int(entry))
            except (FileNotFoundError, ProcessLookupError, PermissionError):
                continue
    for pid in victims:  # until every thread has exited: only then are its files closed
        while any(state != "Z" for state in _thread_states(pid)):
            time.sleep(0.05)
    return victims


def _thread_states(pid: int) -> list:
    states = []
    try:
        for tid in os.listdir(f"/proc/{pid}/task"):
            with open(f"/proc/{pid}/task/{tid}/stat") as fh:
                states.append(fh.read().rsplit(")", 1)[1].split()[0])
    except (FileNotFoundError, ProcessLookupError):
        pass
    return states


def parsph(args, ranks: int = 1, timeout: float = CEILING, cwd=None, env=None) -> subprocess.CompletedProcess:
    """Run `python -m parsph ARGS` on `ranks` ranks (extra environment `env`)."""
    cmd = [sys.executable, "-m", "parsph", *map(str, args)]
    if ranks > 1:
        cmd = [mpiexec(), "-n", str(ranks), *cmd]
    env = {**os.environ, "PYTHONUNBUFFERED": "1", **(env or {})}
    return subprocess.run(cmd, capture_output=True, text=True, timeout=timeout, cwd=cwd or ROOT, env=env)


def parsph_batch(commands: list, ranks: int, folder, env=None) -> list:
    """Run the `parsph` command lines `commands` (argument lists) one after another in one
    MPI job of `ranks` ranks (tests/mpi/cli_batch.py; extra environment `env`), files under
    `folder`; returns for each a subprocess.CompletedProcess as `parsph` would: the ranks'
    highest exit code and their standard output and error, concatenated in rank order. One
    rank is one process without a launcher, as `parsph(..., ranks=1)` runs it."""
    import json

    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    cases = [{"argv": list(map(str, argv)), "out": str(folder / f"case{k}")} for k, argv in enumerate(commands)]
    (folder / "cases.json").write_text(json.dumps(cases))
    cmd = [sys.executable, str(ROOT / "tests" / "mpi" / "cli_batch.py"), str(folder / "cases.json"),
           str(folder / "results.json")]
    if ranks > 1:
        cmd = [mpiexec(), "-n", str(ranks), *cmd]
    env = {**os.environ, "PYTHONUNBUFFERED": "1", **(env or {})}
    job = subprocess.run(cmd, capture_output=True, text=True, timeout=CEILING, cwd=ROOT, env=env)
    assert job.returncode == 0 and (folder / "results.json").exists(), job.stdout + job.stderr
    results = []
    for case, codes in zip(cases, json.loads((folder / "results.json").read_text())):
        out, err = ("".join(Path(f"{case['out']}.{r}.{kind}").read_text() for r in range(ranks))
                    for kind in ("stdout", "stderr"))
        results.append(subprocess.CompletedProcess(case["argv"], max(codes), out, err))
    return results


def parsph_by_ranks(commands: list, folder) -> list:
    """Run the independent `parsph` command lines `commands`, (ranks, argv) each: those on one
    rank count one after another in one MPI job (parsph_batch, files under `folder`), the
    rank counts in turn; returns the CompletedProcess of each, in the order given. (A
    restart goes in a later call than the run that writes its checkpoint.)"""
    results = [None] * len(commands)
    for ranks in sorted({ranks for ranks, _ in commands}):
        mine = [k for k, (n, _) in enumerate(commands) if n == ranks]
        for k, proc in zip(mine, parsph_batch([commands[k][1] for k in mine], ranks, Path(folder) / f"ranks_{ranks}")):
            results[k] = proc
    return results


def assert_runs_by_ranks(commands: list, folder) -> list:
    """parsph_by_ranks, asserting that every command line exits 0; returns the results."""
    results = parsph_by_ranks(commands, folder)
    for (ranks, argv), proc in zip(commands, results):
        assert proc.returncode == 0, f"{' '.join(map(str, argv))} on {ranks} rank(s):\n{proc.stderr}"
    return results


@pytest.fixture
def run_parsph():
    return parsph


def assert_same_on_ranks(scene, args, out_dir, ranks=(1, 3)) -> list:
    """Run `parsph run SCENE ARGS` on each rank count (outputs under out_dir) and assert that
    tools/compare_outputs.py finds every history series and the final state identical;
    returns the output directories (assert_each_same_on_ranks of the one case)."""
    return assert_each_same_on_ranks([(scene, args, out_dir)], Path(out_dir) / "jobs", ranks)[0]


def assert_each_same_on_ranks(cases, folder, ranks=(1, 3)) -> list:
    """assert_same_on_ranks for each (SCENE, ARGS, OUT_DIR) of `cases`, the cases' runs on one
    rank count one after another in one MPI job (parsph_by_ranks, files under `folder`);
    returns each case's output directories."""
    outs = [[Path(out_dir) / f"ranks_{n}" for n in ranks] for _, _, out_dir in cases]
    procs = iter(parsph_by_ranks([(n, ["run", scene, "--out", out, "--quiet", *args])
                                  for (scene, args, _), case_outs in zip(cases, outs)
                                  for n, out in zip(ranks, case_outs)], folder))
    for case_outs in outs:
        for out in case_outs:
            proc = next(procs)
            assert proc.returncode == 0, f"{out}: {proc.stderr}"
    for case_outs in outs:
        assert_identical_outputs(*case_outs)
    return outs


def run_on_ranks(scene, out_dir, ranks=(1, 3)) -> list:
    """Run `parsph run SCENE` on each rank count (outputs under out_dir); returns each run's
    (last snapshot's fields, history)."""
    from parsph.io import read_history, read_snapshots

    results = []
    for n in ranks:
        out = Path(out_dir) / f"ranks_{n}"
        proc = parsph(["run", scene, "--out", out, "--quiet"], ranks=n)
        assert proc.returncode == 0, proc.stderr
        results.append((read_snapshots(out, which=-1)[0].fields, read_history(out)))
    return results


def assert_it_happened(out, ranks: int = 1) -> None:
    """The guard of a comparison of runs: the run in `out` took steps and moved its particles
    (kinetic energy in its history, a displacement in its last snapshot where written) and,
    run on `ranks` ranks, every rank owned particles (the snapshots' owner ranks, where
    written)."""
    import h5py
    import numpy as np

    with h5py.File(Path(out) / "history.h5", "r") as h:
        assert h["step"][-1] > 0 and h["kinetic_energy"][()].max() > 0.0, f"{out}: nothing moved"
    with h5py.File(Path(out) / "snapshots.h5", "r") as f:
        steps = [k for k in f if k.startswith("step_")]
        last = f[max(steps, key=lambda k: int(k[5:]))]
        if "displacement" in last:
            assert np.abs(last["displacement"][()]).max() > 0.0, f"{out}: nothing moved"
        if "rank" in last and ranks > 1:
            owners = set(np.unique(np.concatenate([f[k]["rank"][()] for k in steps])).tolist())
            assert owners == set(range(ranks)), f"{out}: particles only on ranks {sorted(owners)}"


def _compare_outputs():
    """tools/compare_outputs.py as a module (loaded once per test process)."""
    import importlib.util

    module = sys.modules.get("parsph_tools_compare_outputs")
    if module is None:
        spec = importlib.util.spec_from_file_location("parsph_tools_compare_outputs",
                                                      ROOT / "tools" / "compare_outputs.py")
        module = importlib.util.module_from_spec(spec)
        spec.loader.exec_module(module)
        sys.modules[spec.name] = module
    return module


def assert_identical_outputs(*outs) -> None:
    """tools/compare_outputs.py finds every history series and the final state of the runs
    in `outs` identical. Its main is called in this process (what `python
    tools/compare_outputs.py OUTS` prints and returns, without starting Python and importing
    h5py for each comparison)."""
    import contextlib
    import io

    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        code = _compare_outputs().main(list(map(str, outs)))
    assert code == 0 and "identical" in out.getvalue(), \
        f"{' against '.join(map(str, outs))}:\n{out.getvalue()}{err.getvalue()}"


# ---- MPI jobs with more ranks than cores
# MPICH (ch4:ucx) waits for a message by calling ucp_worker_progress in a loop. With more
# ranks than cores (3 ranks, or 2 ranks beside another job, on 2 cores) a waiting rank spins
# through its whole time slice while the rank it waits for is not running: each collective
# then costs ~10 ms, and a 3-rank run of 40 steps takes ~30 s instead of ~3 s. This library,
# preloaded into the processes the tests start, lets a rank that found nothing to do in 256
# polls in a row sleep for a microsecond (gives its core away). Only waiting changes, not
# what is sent or computed; processes that never call ucp_worker_progress (other MPI builds)
# are not affected. PARSPH_TEST_IDLE_SLEEP=0 turns it off; without a C compiler it is not used.
IDLE_SLEEP_C = r"""
#define _GNU_SOURCE
#include <dlfcn.h>
#include <stdio.h>
#include <stdlib.h>
#include <unistd.h>

typedef unsigned (*progress_fn)(void *);
static progress_fn real_progress;
static unsigned idle_polls;

unsigned ucp_worker_progress(void *worker)
{
    if (!real_progress) {
        real_progress = (progress_fn)dlsym(RTLD_NEXT, "ucp_worker_progress");
        if (!real_progress) { /* libucp loaded by a library that was dlopen()ed */
            void *ucp = dlopen("libucp.so.0", RTLD_NOW | RTLD_NOLOAD);
            if (ucp)
                real_progress = (progress_fn)dlsym(ucp, "ucp_worker_progress");
        }
        if (!real_progress) {
            fputs("tests/conftest.py idle-sleep library: ucp_worker_progress not found\n", stderr);
            abort();
        }
    }
    unsigned events = real_progress(worker);
    if (events)
        idle_polls = 0;
    else if (++idle_polls >= 256) {
        idle_polls = 0;
        usleep(1);
    }
    return events;
}
"""
_IDLE_SLEEP_ENV = "PARSPH_TEST_IDLE_SLEEP_LIB"  # set once built: pytest-xdist workers inherit it
_idle_sleep_dir = None


def _build_idle_sleep_library():
    cc = shutil.which("cc") or shutil.which("gcc")
    if cc is None:
        return None
    folder = tempfile.mkdtemp(prefix="parsph-tests-")
    source, library = Path(folder, "idle_sleep.c"), Path(folder, "idle_sleep.so")
    source.write_text(IDLE_SLEEP_C)
    proc = subprocess.run([cc, "-O2", "-shared", "-fPIC", "-o", str(library), str(source), "-ldl"],
                          capture_output=True, text=True)
    if proc.returncode != 0:
        shutil.rmtree(folder, ignore_errors=True)
        return None
    return library


def pytest_configure(config):
    global _idle_sleep_dir
    if os.environ.get("PARSPH_TEST_IDLE_SLEEP", "1") == "0" or os.environ.get(_IDLE_SLEEP_ENV):
        return
    library = _build_idle_sleep_library()
    if library is not None:
        _idle_sleep_dir = library.parent
        os.environ[_IDLE_SLEEP_ENV] = str(library)
        os.environ["LD_PRELOAD"] = " ".join(filter(None, [str(library), os.environ.get("LD_PRELOAD")]))


def pytest_unconfigure(config):
    if _idle_sleep_dir is not None:
        shutil.rmtree(_idle_sleep_dir, ignore_errors=True)


def pytest_report_header(config):
    library = os.environ.get(_IDLE_SLEEP_ENV)
    return [f"MPI jobs: idle ranks sleep ({library} preloaded)" if library else
            "MPI jobs: idle ranks spin (no idle-sleep library: no C compiler, or PARSPH_TEST_IDLE_SLEEP=0)"]


# ---- order (see tools/test: pytest-xdist workers)
def _shares_a_module_fixture(item) -> bool:
    """Does the test use a module- or class-scoped fixture (a run several tests read)?"""
    info = getattr(item, "_fixtureinfo", None)
    defs = info.name2fixturedefs.values() if info is not None else ()
    return any(d and d[-1].scope in ("module", "class") for d in defs)


def pytest_collection_modifyitems(config, items):
    """The long tests first: those marked slow, then those that start MPI jobs, then the
    rest, so that with several workers none is left running a long test alone at the end.
    The tests that share a module-scoped fixture stay next to each other (one run of the
    fixture per worker). Only the order changes (stable sort: the collection order within
    each class)."""
    def rank(item):
        return 0 if item.get_closest_marker("slow") else 1 if item.get_closest_marker("mpi") else 2

    def module(item):
        return item.nodeid.split("::")[0]

    shared = {}
    for item in items:
        if _shares_a_module_fixture(item):
            shared[module(item)] = min(shared.get(module(item), 2), rank(item))
    items.sort(key=lambda item: shared.get(module(item), rank(item)) if _shares_a_module_fixture(item)
               else rank(item))
