"""Failures during a run: an error only one rank sees must end every rank, in bounded time.

The scene is the 1D bar of runs/bar1d.toml (40 particles on [0, 1] m) whose right-end
particle starts at -1e6 m/s: in the first step it moves ~2.5 m to the left, through its
neighbours, so particles at the right end invert (J <= 0). Ranks own particles by
recursive coordinate bisection of their positions, so the right end belongs to the last
rank and only that rank detects the inversion; the other ranks are then waiting in a
collective (the time-step reduction) and must not hang.

The law is compressible neo-Hookean (with poisson_ratio = 0, lambda = 0): it returns NaN
for J <= 0, so the inversion is reported in the step where it happens.
"""

from __future__ import annotations

import os
import re
import signal
import subprocess
import sys
import time

import pytest

from conftest import BAR, ROOT, mpiexec

# the bar of runs/bar1d.toml, neo-Hookean, with its tip thrown left at 1e6 m/s: it inverts
BAR = (BAR.replace('name = "bar1d"', 'name = "bar1d_inverting"')
       .replace('model = "saint_venant_kirchhoff"', 'model = "neo_hookean"')
       .replace('group = "right_quarter"\nvalue = [5.0]', 'group = "B"\nvalue = [-1.0e6]'))

TIMEOUT = 60.0  # seconds; a healthy failing job ends in a few seconds
BOUND = 30.0  # the job must end well before the timeout
INVERTED = re.compile(r"particle (3[5-9]) .*inverted")  # one of the right-end particles


def launch(args, ranks: int, timeout: float):
    """Like conftest.parsph, but the job runs in its own session, so that a hung job is
    killed with all its ranks (not only mpiexec) before the test fails."""
    cmd = [sys.executable, "-m", "parsph", *map(str, args)]
    if ranks > 1:
        cmd = [mpiexec(), "-n", str(ranks), *cmd]
    env = dict(os.environ, PYTHONUNBUFFERED="1")
    with subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, cwd=ROOT,
                          env=env, start_new_session=True) as proc:
        try:
            out, err = proc.communicate(timeout=timeout)
        except subprocess.TimeoutExpired:
            os.killpg(proc.pid, signal.SIGKILL)
            out, err = proc.communicate()
            pytest.fail(f"the job on {ranks} rank(s) did not end within {timeout} s (killed)\n"
                        f"stdout:\n{out}\nstderr:\n{err}")
    return subprocess.CompletedProcess(cmd, proc.returncode, out, err)


def run_failing(tmp_path, ranks: int, text: str = BAR, max_steps: int = 200):
    scene = tmp_path / "scene.toml"
    scene.write_text(text)
    start = time.monotonic()
    args = ["run", scene, "--out", tmp_path / "out", "--quiet", "--set", f"time.max_steps={max_steps}"]
    proc = launch(args, ranks, TIMEOUT)
    return proc, time.monotonic() - start


@pytest.mark.mpi
@pytest.mark.parametrize("ranks", [2, 3])
def test_one_rank_failing_mid_run_ends_all_ranks(ranks, tmp_path):
    proc, seconds = run_failing(tmp_path, ranks)
    err = proc.stderr
    assert seconds < BOUND, f"the job took {seconds:.1f} s to end"
    assert proc.returncode != 0, f"exit code 0\nstdout:\n{proc.stdout}\nstderr:\n{err}"
    assert "Traceback" not in err, err  # a solver error, not a crash
    found = INVERTED.findall(err)
    assert len(found) == 1, f"expected one message naming an inverted particle in:\n{err}"
    assert f"error on rank {ranks - 1}:" in err, err  # the rank that owns the right end
    assert "parsph: scene 'bar1d_inverting'" in proc.stdout  # set-up was over: it failed mid-run


def test_inverted_particle_on_one_rank_exit_1(tmp_path):
    proc, seconds = run_failing(tmp_path, 1)
    err = proc.stderr
    assert proc.returncode == 1, f"exit code {proc.returncode}\nstderr:\n{err}"
    assert len(INVERTED.findall(err)) == 1, err
    assert err.count("parsph: error:") == 1, err
    assert "Traceback" not in err, err


def test_inverted_particle_saint_venant_kirchhoff_is_reported(tmp_path):
    text = BAR.replace('model = "neo_hookean"', 'model = "saint_venant_kirchhoff"')
    proc, _ = run_failing(tmp_path, 1, text, max_steps=2)
    assert proc.returncode == 1, f"exit code {proc.returncode}\nstderr:\n{proc.stderr}"
    assert INVERTED.search(proc.stderr), proc.stderr
