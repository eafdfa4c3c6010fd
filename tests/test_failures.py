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
import threading
import time

import h5py
import numpy as np
import pytest

from conftest import BAR, ROOT, RUNS, mpiexec

# the bar of runs/bar1d.toml, neo-Hookean, with its tip thrown left at 1e6 m/s: it inverts
BAR = (BAR.replace('name = "bar1d"', 'name = "bar1d_inverting"')
       .replace('model = "saint_venant_kirchhoff"', 'model = "neo_hookean"')
       .replace('group = "right_quarter"\nvalue = [5.0]', 'group = "B"\nvalue = [-1.0e6]'))

CEILING = 900.0  # seconds: only a real hang gets near it (a cold compile under load takes a minute)
AFTER_FAILURE = 60.0  # seconds from the failing rank's message to the end of every rank (healthy: ~1 s)
INVERTED = re.compile(r"particle (3[5-9]) .*inverted")  # one of the right-end particles


def launch(args, ranks: int):
    """Like conftest.parsph, but the job runs in its own session, so that a hung job is
    killed with all its ranks (not only mpiexec) before the test fails. Returns the process
    and the seconds from the first error message on stderr to the end of the job (None if
    there was none): how long the other ranks took to follow the failing one, whatever the
    set-up and compiles before it cost."""
    cmd = [sys.executable, "-m", "parsph", *map(str, args)]
    if ranks > 1:
        cmd = [mpiexec(), "-n", str(ranks), *cmd]
    env = dict(os.environ, PYTHONUNBUFFERED="1")
    out, err, failed_at = [], [], []

    def read(stream, lines):
        for line in stream:
            if not failed_at and "parsph: error" in line:
                failed_at.append(time.monotonic())
            lines.append(line)

    with subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, cwd=ROOT,
                          env=env, start_new_session=True) as proc:
        readers = [threading.Thread(target=read, args=args, daemon=True)
                   for args in ((proc.stdout, out), (proc.stderr, err))]
        for reader in readers:
            reader.start()
        try:
            proc.wait(timeout=CEILING)
        except subprocess.TimeoutExpired:
            os.killpg(proc.pid, signal.SIGKILL)
            proc.wait()
            pytest.fail(f"the job on {ranks} rank(s) did not end within {CEILING} s (killed)\n"
                        f"stderr:\n{''.join(err)}")
        finally:
            ended = time.monotonic()
            for reader in readers:
                reader.join()
    seconds = ended - failed_at[0] if failed_at else None
    return subprocess.CompletedProcess(cmd, proc.returncode, "".join(out), "".join(err)), seconds


def run_failing(tmp_path, ranks: int, text: str = BAR, max_steps: int = 200):
    scene = tmp_path / "scene.toml"
    scene.write_text(text)
    args = ["run", scene, "--out", tmp_path / "out", "--quiet", "--set", f"time.max_steps={max_steps}"]
    return launch(args, ranks)


@pytest.mark.mpi
@pytest.mark.parametrize("ranks", [2, 3])
def test_one_rank_failing_mid_run_ends_all_ranks(ranks, tmp_path):
    proc, seconds = run_failing(tmp_path, ranks)
    err = proc.stderr
    assert seconds is not None and seconds < AFTER_FAILURE, \
        f"the job took {seconds} s from the failing rank's message to its end\n{err}"
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


# ---- values beyond double precision: the run stops before it writes inf or nan
BAR_SVK = BAR.replace('model = "neo_hookean"', 'model = "saint_venant_kirchhoff"')
NOT_FINITE = {
    "initial-velocity-1e200": (BAR_SVK.replace("value = [-1.0e6]", "value = [1.0e200]"),
                               ["history row at step 0", "kinetic_energy = inf",
                                "particle 39 is the first whose kinetic energy is not finite"]),
    "wall-at-1e250-m/s": (BAR_SVK.replace("value = [-1.0e6]", "value = [0.0]")
                          + "\n[[walls]]\npoint = [1.0]\nnormal = [-1.0]\nvelocity = [-1.0e250]\n",
                          ["kinetic_energy = inf", "external_work = inf", "is the first whose kinetic energy"]),
    "body-acceleration-1e305": (BAR_SVK.replace("value = [-1.0e6]", "value = [0.0]")
                                + "\n[loads]\nbody_acceleration = [1.0e305]\n",
                                ["particle 0 at (0) has a stress that is not finite (J = 3.036e+295) at step 1"]),
}


@pytest.mark.parametrize("case, ranks", [(case, 1) for case in NOT_FINITE]
                         + [pytest.param("initial-velocity-1e200", 2, marks=pytest.mark.mpi)])
def test_a_value_beyond_double_precision_stops_the_run_before_it_is_written(case, ranks, tmp_path):
    """Exit 1 with one message naming the series or the particle and the step; the history
    holds only the finite rows written before."""
    text, expect = NOT_FINITE[case]
    proc, _ = run_failing(tmp_path, ranks, text.replace('name = "bar1d_inverting"', 'name = "overflow"')
                          .replace("history_interval = 1.0e-5", "history_interval = 0.0\nhistory_every = 1"))
    err = proc.stderr
    assert proc.returncode == 1, f"exit code {proc.returncode}\nstderr:\n{err}"
    assert err.count("parsph: error") == 1 and "Traceback" not in err and "Abort" not in err, err
    for part in expect:
        assert part in err, f"{part!r} not in:\n{err}"
    with h5py.File(tmp_path / "out" / "history.h5", "r") as f:
        rows = {name: f[name][()] for name in f}
    step = int(re.search(r"at step (\d+)", err).group(1))
    assert all(len(v) == step for v in rows.values())  # a row per step before the failing one
    assert all(np.isfinite(v).all() for v in rows.values())


@pytest.mark.parametrize("ranks", [1, pytest.param(2, marks=pytest.mark.mpi)])
def test_a_step_far_beyond_the_stable_one_ends_naming_an_inverted_particle(ranks, tmp_path):
    """The Taylor bar ([G §4.5], paper hourglass form, a wall) at 150 times its stable step:
    particles pile up on the wall (some coincide, where the paper form's central force has
    no direction) and invert; the run ends with exit 1 naming one, on every rank count."""
    args = ["run", RUNS / "taylor_impact.toml", "--out", tmp_path / "out", "--quiet", "--set", "time.end=4e-6",
            "--set", "time.dt=1e-6", "--set", "parameters.length=7e-3"]
    proc, seconds = launch(args, ranks)
    err = proc.stderr
    assert proc.returncode == 1, f"exit code {proc.returncode}\nstderr:\n{err}"
    assert "Traceback" not in err and err.count("parsph: error") == 1, err
    assert re.search(r"particle \d+ at \(.*\) is inverted \(J = .*\) at step \d+, .*reduce time.dt = 1e-06 s", err), err
    assert seconds < AFTER_FAILURE, f"{seconds} s from the message to the end of the job"


def test_a_signal_while_a_failing_run_closes_its_outputs_waits_for_them(tmp_path):
    """SIGTERM arriving while a failing run closes its outputs (its history's last rows) is
    held until they are whole: the run ends with its own failure (exit 1, the inverted
    particle named), not killed by the signal, and its history file reads."""
    scene = tmp_path / "scene.toml"
    scene.write_text(BAR)
    script = ("import os, signal, sys\n"
              "from parsph.io import outputs\n"
              "close = outputs.Outputs.close\n"
              "def signalled(self):\n"
              "    os.kill(os.getpid(), signal.SIGTERM)\n"
              "    close(self)\n"
              "outputs.Outputs.close = signalled\n"
              "from parsph.cli import main\n"
              "sys.exit(main(sys.argv[1:]))\n")
    proc = subprocess.run([sys.executable, "-c", script, "run", str(scene), "--out", str(tmp_path / "out"),
                           "--quiet", "--set", "time.max_steps=200"], cwd=ROOT, capture_output=True, text=True,
                          timeout=CEILING)
    assert proc.returncode == 1, f"exit code {proc.returncode}\nstderr:\n{proc.stderr}"
    assert len(INVERTED.findall(proc.stderr)) == 1, proc.stderr
    with h5py.File(tmp_path / "out" / "history.h5", "r") as f:
        assert len(f["time"]) >= 1 and np.isfinite(f["kinetic_energy"][()]).all()
