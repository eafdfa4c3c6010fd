"""Checkpoints and restart: exact continuation, other rank counts, kills, corrupt files."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time

import h5py
import numpy as np
import pytest

from conftest import (CEILING, ROOT, RUNS, assert_runs_by_ranks, kill_processes_mentioning, mpiexec, parsph,
                      parsph_batch, wait_for)
from parsph.io import read_history, read_snapshots

FIELDS = '["position","velocity","J"]'
PATCH = ["--set", f"output.snapshot_fields={FIELDS}", "--set", "output.history_every=10",
         "--set", "output.history_interval=0.0"]


def final(out, names=("position", "velocity", "J")):
    last = read_snapshots(out, names, which=-1)[0]
    return last.step, last.fields


def history(out):
    return read_history(out)


# The runs stopped by a signal, a kill or the wall clock get as far as the machine's speed
# takes them in a second or two: the 1D bar, whose small vibration the default step keeps
# bounded for ever (the random patch's large one outgrows it after about 60 periods).
ENDLESS = ["--set", "time.end=1000"]


def run(out, ranks, *extra, scene="patch_random", env=None):
    proc = parsph(["run", RUNS / f"{scene}.toml", "--out", out, "--quiet", *PATCH, *extra],
                  ranks=ranks, env=env)
    assert proc.returncode == 0, proc.stderr
    return proc


@pytest.fixture(scope="module")
def straight(tmp_path_factory):
    """patch_random straight to step 80 on one rank: the answer on every rank count."""
    out = tmp_path_factory.mktemp("straight")
    run(out, 1, "--set", "time.max_steps=80")
    return out


@pytest.mark.mpi
@pytest.mark.parametrize("first, second, serial_hdf5", [(1, 1, False), (2, 2, False), (1, 3, False),
                                                        (3, 2, False), (2, 2, True)])
def test_restart_continues_bit_for_bit(tmp_path, straight, first, second, serial_hdf5):
    """Stopped at step 40 on `first` ranks and continued on `second`: the same files as the
    straight run (one rank; the answer does not depend on the rank count)."""
    env = {"PARSPH_SERIAL_HDF5": "1"} if serial_hdf5 else None
    split = tmp_path / "split"
    run(split, first, "--set", "time.max_steps=40", "--set", "output.checkpoint_every=40", env=env)
    assert (split / "checkpoints" / "step_00000040.h5").exists()
    proc = run(split, second, "--set", "time.max_steps=80", "--restart", "latest", env=env)
    assert "restarting from" in proc.stdout
    step_a, a = final(straight)
    step_b, b = final(split)
    assert step_a == step_b == 80
    for field in a:
        assert np.array_equal(a[field], b[field]), field
    ha, hb = history(straight), history(split)
    assert np.array_equal(ha["step"], hb["step"])  # no gap, no duplicate row
    assert sorted(ha) == sorted(hb)
    for name in ha:  # every series, bit for bit: sums over particles are exact
        assert np.array_equal(ha[name], hb[name]), name


@pytest.mark.mpi
def test_updated_reference_restart_continues_bit_for_bit(tmp_path):
    """Rings (updated reference every 3 steps, wall contact): a checkpoint between updates
    (step 20) restarted on another rank count continues exactly."""
    # 50 m/s, faster than the rubber's waves: the ring is crushed at t = 0.3 ms; 40 steps at
    # time.cfl = 0.15 end before
    ring = ["--set", "parameters.spacing=4e-3", "--set", "initial.0.value=[-50.0, 0.0]", "--set", "time.cfl=0.15"]
    straight, split = tmp_path / "straight", tmp_path / "split"
    rings = ["run", RUNS / "rings.toml", "--quiet", *PATCH, *ring, "--out"]
    # the straight and the stopped run in one MPI job (conftest.parsph_by_ranks), then the restart
    assert_runs_by_ranks([(2, [*rings, straight, "--set", "time.max_steps=40"]),
                          (2, [*rings, split, "--set", "time.max_steps=20", "--set", "output.checkpoint_every=20"])],
                         tmp_path / "batch")
    run(split, 3, "--set", "time.max_steps=40", "--restart", "latest", *ring, scene="rings")
    _, a = final(straight)
    _, b = final(split)
    for field in a:
        assert np.array_equal(a[field], b[field]), field
    ha, hb = history(straight), history(split)
    assert np.array_equal(ha["reference_updates"], hb["reference_updates"])
    assert ha["reference_updates"][-1] == 13


def straight_and_restarted(tmp_path, cases: dict) -> None:
    """Each scene of `cases` (name -> its extra command-line options) run straight to step 80
    and stopped at step 40 with a checkpoint, all on 2 ranks in one MPI job
    (conftest.parsph_by_ranks), then the stopped runs restarted on 3 ranks to step 80 in
    another: TMP/SCENE/straight and TMP/SCENE/split."""
    def command(scene, out, *extra):
        return ["run", RUNS / f"{scene}.toml", "--out", out, "--quiet", *PATCH, *cases[scene], *extra]

    assert_runs_by_ranks([(2, command(scene, tmp_path / scene / out, *extra)) for scene in cases
                          for out, extra in (("straight", ["--set", "time.max_steps=80"]),
                                             ("split", ["--set", "time.max_steps=40",
                                                        "--set", "output.checkpoint_every=40"]))],
                         tmp_path / "batch")
    assert_runs_by_ranks([(3, command(scene, tmp_path / scene / "split", "--set", "time.max_steps=80",
                                      "--restart", "latest")) for scene in cases], tmp_path / "batch_restart")


@pytest.mark.mpi
def test_plastic_state_restart_continues_bit_for_bit(tmp_path):
    """Taylor bar (J2 plasticity at the particles, wall contact) and steel ring (at KBM's
    stress points too): a checkpoint while they yield (step 40), restarted on another rank
    count, continues exactly, plastic strain and energies too."""
    names = ("position", "velocity", "J", "plastic_strain", "plastic_work")
    fields = ["--set", "output.snapshot_fields=" + str(list(names)).replace("'", '"')]
    scenes = ("taylor_impact", "ring_shear_bands")
    straight_and_restarted(tmp_path, {scene: fields for scene in scenes})
    for scene in scenes:
        _, a = final(tmp_path / scene / "straight", names)
        _, b = final(tmp_path / scene / "split", names)
        assert a["plastic_strain"].max() > 0, scene
        for field in a:
            assert np.array_equal(a[field], b[field]), (scene, field)
        ha, hb = history(tmp_path / scene / "straight"), history(tmp_path / scene / "split")
        for name in ("plastic_work", "external_work", "total_energy"):
            assert np.array_equal(ha[name], hb[name]), (scene, name)


@pytest.mark.mpi
def test_forces_that_read_the_velocity_restart_bit_for_bit(tmp_path):
    """Monaghan's viscosity (the flyer plate) and MACHDYN's viscous hourglass dampers (the
    Taylor bar) read the velocity, which their evaluation sees after the step's first
    half-kick: a checkpoint on 2 ranks (step 40), restarted on 3, continues exactly, the
    velocity, the viscous work and the energies too (a restart evaluating them at the step's
    end velocity did not)."""
    cases = {"flyer_plate": [], "taylor_impact": ["--set", "formulation.plastic_hourglass=viscous"]}
    straight_and_restarted(tmp_path, cases)
    for scene in cases:
        _, a = final(tmp_path / scene / "straight")
        _, b = final(tmp_path / scene / "split")
        for field in a:
            assert np.array_equal(a[field], b[field]), (scene, field)
        ha, hb = history(tmp_path / scene / "straight"), history(tmp_path / scene / "split")
        for name in ("viscous_work", "hourglass_energy", "external_work", "total_energy"):
            assert np.array_equal(ha[name], hb[name]), (scene, name)


def test_restart_refuses_other_physics_and_allows_a_new_end_time(tmp_path):
    out = tmp_path / "run"
    run(out, 1, "--set", "time.max_steps=20", "--set", "output.checkpoint_every=10")
    # the refused restart and the allowed one one after another in one process (conftest.parsph_batch)
    refusal, proc = parsph_batch([
        ["run", RUNS / "patch_random.toml", "--out", out, "--restart", "latest",
         "--set", "material.density=2.0", "--set", "formulation.hourglass=10"],
        ["run", RUNS / "patch_random.toml", "--out", out, "--restart", "latest", "--quiet",
         *PATCH, "--set", "time.end=0.8"]], 1, tmp_path / "batch")
    assert refusal.returncode == 2
    assert "material.density" in refusal.stderr and "formulation.hourglass" in refusal.stderr
    assert proc.returncode == 0, proc.stderr
    with h5py.File(out / "history.h5", "r") as f:
        assert f["time"][-1] >= 0.8


@pytest.mark.parametrize("ranks", [1, pytest.param(2, marks=pytest.mark.mpi)])
def test_restart_refusal_names_the_changed_keys_of_bodies_and_contact(tmp_path, ranks):
    out = tmp_path / "run"
    # the run and the refused restart one after another in one MPI job (conftest.parsph_batch)
    first, proc = parsph_batch([
        ["run", RUNS / "bars_impact.toml", "--out", out, "--quiet", *PATCH, "--set", "time.max_steps=20",
         "--set", "output.checkpoint_every=10"],
        ["run", RUNS / "bars_impact.toml", "--out", out, "--restart", "latest", *PATCH,
         "--set", "contact.0.stiffness=2.0", "--set", "bodies.1.material.density=7000.0"]], ranks, tmp_path / "batch")
    assert first.returncode == 0, first.stderr
    assert proc.returncode == 2 and "Traceback" not in proc.stderr, proc.stderr
    assert proc.stderr.count("parsph: error") == 1, proc.stderr
    assert "differs from checkpoint" in proc.stderr
    assert "in bodies.1.material.density, contact.0.stiffness;" in proc.stderr, proc.stderr


@pytest.mark.parametrize("ranks", [1, pytest.param(3, marks=pytest.mark.mpi)])
def test_corrupt_and_truncated_checkpoints_are_refused_and_latest_skips_them(tmp_path, ranks):
    """The ranks hash the file's chunks among them: a changed last velocity (the end of the
    file) and a truncated file are found, and every rank refuses the file."""
    out = tmp_path / "run"
    run(out, ranks, "--set", "time.max_steps=30", "--set", "output.checkpoint_every=10",
        "--set", "output.checkpoint_keep=3")
    folder = out / "checkpoints"
    names = sorted(p.name for p in folder.glob("step_*.h5"))
    assert names == ["step_00000010.h5", "step_00000020.h5", "step_00000030.h5"]
    # flip bytes inside the last velocity of the newest, truncate the second newest
    newest = folder / names[-1]
    with h5py.File(newest, "r") as f:
        end = f["v"].id.get_offset() + f["v"].id.get_storage_size()
    data = bytearray(newest.read_bytes())
    data[end - 8: end] = b"\xff" * 8
    newest.write_bytes(bytes(data))
    middle = folder / names[-2]
    middle.write_bytes(middle.read_bytes()[:2000])
    # the two refusals and the restart one after another in one MPI job (conftest.parsph_batch)
    commands = [["run", RUNS / "patch_random.toml", "--out", out, "--restart", path] for path in (newest, middle)]
    commands.append(["run", RUNS / "patch_random.toml", "--out", out, "--restart", "latest", "--quiet",
                     *PATCH, "--set", "time.max_steps=40"])
    *refusals, proc = parsph_batch(commands, ranks, tmp_path / "batch")
    for refusal, why in zip(refusals, ("is damaged", "is damaged or truncated")):
        assert refusal.returncode == 2 and why in refusal.stderr and "Traceback" not in refusal.stderr, refusal.stderr
    assert proc.returncode == 0, proc.stderr
    assert "skipping checkpoint" in proc.stdout
    assert "step_00000010.h5" in proc.stdout.split("restarting from")[1].splitlines()[0]


@pytest.mark.mpi
@pytest.mark.parametrize("serial_hdf5", [False, True])
def test_killed_run_leaves_readable_files_and_a_restartable_checkpoint(tmp_path, serial_hdf5):
    out = tmp_path / "run"
    env = dict(os.environ, PARSPH_SERIAL_HDF5="1" if serial_hdf5 else "0")
    cmd = [mpiexec(), "-n", "2", sys.executable, "-m", "parsph", "run", str(RUNS / "bar1d.toml"),
           "--out", str(out), "--quiet", *PATCH, "--set", "output.checkpoint_every=200",
           "--set", "output.snapshot_interval=0.5", *ENDLESS]
    proc = subprocess.Popen(cmd, cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            start_new_session=True, env=env)
    wait_for(lambda: list((out / "checkpoints").glob("step_*.h5")), poll=0.2)
    time.sleep(np.random.default_rng().uniform(0.5, 3.0))  # a random moment after a checkpoint
    victims = kill_processes_mentioning(str(out))  # the ranks and the launcher, like an OOM kill
    assert len(victims) >= 2, proc.communicate()  # the job was still running
    proc.wait(timeout=CEILING)
    with h5py.File(out / "history.h5", "r") as f:
        assert len(f["time"]) > 0 and np.all(np.isfinite(f["kinetic_energy"][()]))
    with h5py.File(out / "snapshots.h5", "r") as f:
        assert any(k.startswith("step_") for k in f)
    proc = parsph(["run", RUNS / "bar1d.toml", "--out", out, "--restart", "latest", "--quiet",
                   *PATCH, *ENDLESS, "--set", "time.wall_limit=1"], ranks=2, env=env)
    assert proc.returncode == 0, proc.stderr


def test_sigterm_writes_a_checkpoint_and_stops(tmp_path):
    out = tmp_path / "run"
    cmd = [sys.executable, "-m", "parsph", "run", str(RUNS / "bar1d.toml"), "--out", str(out),
           "--quiet", *PATCH, *ENDLESS]
    proc = subprocess.Popen(cmd, cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    wait_for(lambda: (out / "history.h5").exists(), poll=0.2)
    time.sleep(1.0)
    proc.send_signal(signal.SIGTERM)
    stdout, stderr = proc.communicate(timeout=CEILING)
    assert proc.returncode == 128 + signal.SIGTERM, stderr
    assert "stopped by SIGTERM" in stdout and "--restart latest" in stdout
    assert list((out / "checkpoints").glob("step_*.h5"))


def test_wall_clock_limit_checkpoints_and_exits_cleanly(tmp_path):
    out = tmp_path / "run"
    proc = run(out, 1, "--set", "time.wall_limit=1.0", *ENDLESS, scene="bar1d")
    assert "stopped by the wall-clock limit" in proc.stdout
    assert list((out / "checkpoints").glob("step_*.h5"))


@pytest.mark.mpi
@pytest.mark.parametrize("serial_hdf5", [False, True])
def test_xdmf_of_a_three_rank_run_reads_back_with_meshio(tmp_path, serial_hdf5):
    meshio = pytest.importorskip("meshio")
    out = tmp_path / "run"
    proc = run(out, 3, "--set", "time.end=1.0", "--set", "output.snapshot_interval=0.25",
               "--set", 'output.snapshot_fields=["position","displacement","velocity","J","rank","cauchy_stress"]',
               env={"PARSPH_SERIAL_HDF5": "1" if serial_hdf5 else "0"})
    assert ("written there" in proc.stderr) == serial_hdf5  # the fallback says so
    with meshio.xdmf.TimeSeriesReader(str(out / "snapshots.xdmf")) as reader:
        points, cells = reader.read_points_cells()
        assert points.shape == (444, 3) and cells[0].type == "vertex" and len(cells[0].data) == 444
        assert reader.num_steps == 5
        times = []
        for k in range(reader.num_steps):
            t, point_data, _ = reader.read_data(k)
            times.append(t)
            assert point_data["displacement"].shape == (444, 2)
            assert point_data["velocity"].shape == (444, 2)
            assert point_data["J"].shape == (444,)
            assert point_data["cauchy_stress"].shape == (444, 2, 2)
            assert sorted(np.unique(point_data["rank"])) == [0, 1, 2]
        assert times == sorted(times) and times[-1] >= 1.0
