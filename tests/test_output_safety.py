"""The output directory: one run at a time, --overwrite replaces the whole run, restarts
never cut what was written, a full or unwritable disk ends with one message and readable
files, and a restarted run's files equal an uninterrupted run's."""

from __future__ import annotations

import os
import shlex
import signal
import subprocess
import sys
import time

import h5py
import numpy as np
import pytest

from conftest import BAR, CEILING, ROOT, RUNS, mpiexec, parsph, parsph_batch, wait_for

HISTORY = ["--set", "output.history_every=5", "--set", "output.history_interval=0.0"]


@pytest.fixture
def bar(tmp_path):
    scene = tmp_path / "bar.toml"
    scene.write_text(BAR)
    return scene


def run_ok(args, ranks=1):
    proc = parsph(["run", *args, "--quiet"], ranks=ranks)
    assert proc.returncode == 0, proc.stderr
    return proc


def refused(proc, *words, code=2):
    """The run ended with `code`, one message naming `words`, and no traceback."""
    err = proc.stderr
    assert proc.returncode == code, f"exit {proc.returncode}\n{proc.stdout}\n{err}"
    assert "Traceback" not in err, err
    assert err.count("parsph: error") == 1, err
    for w in words:
        assert w in err, f"{w!r} not in:\n{err}"


def files_of(out):
    return {p.relative_to(out).as_posix(): p.read_bytes() for p in sorted(out.rglob("*"))
            if p.is_file() and p.name != ".parsph.lock"}


def all_series(path):
    with h5py.File(path, "r") as f:
        return {k: f[k][()] for k in f}


def snapshots_of(path):
    with h5py.File(path, "r") as f:
        return {g: {k: f[g][k][()] for k in f[g]} | {"@time": f[g].attrs["time"]}
                for g in f if g.startswith("step_")}


def assert_same_run(a, b):
    """Two output directories hold the same history and snapshots, bit for bit, and the
    same XDMF index."""
    ha, hb = all_series(a / "history.h5"), all_series(b / "history.h5")
    assert sorted(ha) == sorted(hb)
    for k in ha:
        assert np.array_equal(ha[k], hb[k]), k
    sa, sb = snapshots_of(a / "snapshots.h5"), snapshots_of(b / "snapshots.h5")
    assert sorted(sa) == sorted(sb)
    for g in sa:
        for k in sa[g]:
            assert np.array_equal(sa[g][k], sb[g][k]), (g, k)
    assert (a / "snapshots.xdmf").read_text() == (b / "snapshots.xdmf").read_text()


def test_overwrite_removes_the_previous_runs_checkpoints(bar, tmp_path):
    out = tmp_path / "out"
    run_ok([bar, "--out", out, "--set", "time.max_steps=200", "--set", "output.checkpoint_every=50"])
    assert sorted(p.name for p in (out / "checkpoints").glob("*.h5")) == ["step_00000150.h5", "step_00000200.h5"]
    proc = parsph(["run", bar, "--out", out, "--quiet", "--set", "time.max_steps=60"])
    refused(proc, "already holds a run", "checkpoints")
    run_ok([bar, "--out", out, "--overwrite", "--set", "time.max_steps=60", "--set", "output.checkpoint_every=20"])
    assert sorted(p.name for p in (out / "checkpoints").glob("*.h5")) == ["step_00000040.h5", "step_00000060.h5"]
    proc = run_ok([bar, "--out", out, "--restart", "latest", "--set", "time.max_steps=80",
                   "--set", "output.checkpoint_every=20"])
    assert "step_00000060.h5" in proc.stdout
    steps = all_series(out / "history.h5")["step"]
    assert steps[-1] == 80 and np.all(np.diff(steps) > 0)


def _start(args):
    return subprocess.Popen([sys.executable, "-m", "parsph", "run", *map(str, args), "--quiet"], cwd=ROOT,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, start_new_session=True)


def test_a_second_run_into_a_directory_in_use_is_refused_and_a_killed_run_frees_it(bar, tmp_path):
    out = tmp_path / "out"
    first = _start([bar, "--out", out, "--set", "time.end=1e3", "--set", "output.checkpoint_every=100"])
    try:
        wait_for(lambda: list((out / "checkpoints").glob("step_*.h5")), poll=0.1)
        before = (out / "scene.json").read_bytes()
        # the three attempts one after another in one process (conftest.parsph_batch)
        for proc in parsph_batch([["run", bar, "--out", out, "--quiet", "--set", "time.end=1e3", *extra]
                                  for extra in ([], ["--overwrite"], ["--restart", "latest"])], 1, tmp_path / "batch"):
            refused(proc, "in use by another run", f"pid {first.pid}")
        assert first.poll() is None, "the first run was disturbed"
        assert (out / "scene.json").read_bytes() == before
    finally:
        os.killpg(first.pid, signal.SIGKILL)
        first.communicate()
    proc = parsph(["run", bar, "--out", out, "--quiet", "--restart", "latest", "--set", "time.end=1e3",
                   "--set", "time.wall_limit=0.5"])
    assert proc.returncode == 0, proc.stderr  # the kill left no stale lock
    assert "stopped by the wall-clock limit" in proc.stdout


def test_restart_to_an_earlier_end_is_refused_and_keeps_the_output(bar, tmp_path):
    out = tmp_path / "out"
    run_ok([bar, "--out", out, "--set", "time.max_steps=100", "--set", "output.checkpoint_every=50",
            "--set", "output.snapshot_interval=1e-4"])
    before = files_of(out)
    for change in (["--set", "time.max_steps=60"], ["--set", "time.max_steps=100", "--set", "time.end=1e-4"]):
        proc = parsph(["run", bar, "--out", out, "--quiet", "--restart", "latest", *change])
        refused(proc, "already holds the run to step 100", "later end")
        assert files_of(out) == before


def test_a_restart_into_the_output_of_another_scene_is_refused_unless_overwrite(bar, tmp_path):
    """Scene B's checkpoint continued with --out at scene A's finished run must neither cut
    A's history nor remove A's snapshots and checkpoints; with --overwrite B replaces A."""
    other = tmp_path / "other.toml"
    other.write_text(BAR.replace("density = 7850.0", "density = 2700.0"))
    a, b = tmp_path / "a", tmp_path / "b"
    options = ["--set", "output.checkpoint_every=20", "--set", "output.snapshot_interval=2e-4"]
    run_ok([bar, "--out", a, "--set", "time.max_steps=60", *options])
    run_ok([other, "--out", b, "--set", "time.max_steps=40", *options])
    before = files_of(a)
    checkpoint = b / "checkpoints" / "step_00000020.h5"
    proc = parsph(["run", other, "--out", a, "--quiet", "--restart", checkpoint, "--set", "time.max_steps=80"])
    refused(proc, f"{a} holds a run of another scene than checkpoint {checkpoint}", "material.density",
            "--overwrite")
    assert files_of(a) == before
    run_ok([other, "--out", a, "--overwrite", "--restart", checkpoint, "--set", "time.max_steps=40", *options])
    assert sorted(p.name for p in (a / "checkpoints").glob("*.h5")) == ["step_00000040.h5"]
    steps = all_series(a / "history.h5")["step"]
    assert steps[0] > 20 and steps[-1] == 40 and np.all(np.diff(steps) > 0)
    assert all_series(a / "history.h5")["tip_displacement"][-1] == all_series(b / "history.h5")["tip_displacement"][-1]


@pytest.mark.parametrize("damaged", ["history.h5", "snapshots.h5"])
def test_restart_with_a_damaged_history_or_snapshot_file_is_refused(bar, tmp_path, damaged):
    out = tmp_path / "out"
    run_ok([bar, "--out", out, "--set", "time.max_steps=40", "--set", "output.checkpoint_every=20"])
    path = out / damaged
    data = bytearray(path.read_bytes())
    data[: len(data) // 2] = bytes(len(data) // 2)  # the superblock and root group zeroed
    path.write_bytes(bytes(data))
    before = files_of(out)
    fresh = tmp_path / "fresh"
    # the refused restart and the advised one (from the checkpoint into a fresh directory) one
    # after another in one process (conftest.parsph_batch)
    proc, advised = parsph_batch([
        ["run", bar, "--out", out, "--quiet", "--restart", "latest", "--set", "time.max_steps=60"],
        ["run", bar, "--out", fresh, "--restart", out / "checkpoints" / "step_00000040.h5",
         "--set", "time.max_steps=60", "--quiet"]], 1, tmp_path / "batch")
    refused(proc, damaged, "--restart CHECKPOINT_FILE")
    assert files_of(out) == before
    assert advised.returncode == 0, advised.stderr  # the advice works
    assert all_series(fresh / "history.h5")["step"][-1] == 60


def test_unusable_output_paths_are_refused(bar, tmp_path):
    blocker = tmp_path / "a_file"
    blocker.write_text("x")
    link = tmp_path / "dangling"
    link.symlink_to(tmp_path / "nowhere")
    # the three runs one after another in one process (conftest.parsph_batch)
    procs = parsph_batch([["run", bar, "--out", where, "--quiet"] for where in (blocker / "sub", blocker, link)], 1,
                         tmp_path / "batch")
    for proc, words in zip(procs, ("a_file", "not a directory", "dangling symbolic link")):
        refused(proc, words)
    assert blocker.read_text() == "x"


def _mount_tmpfs(where, options):
    where.mkdir()
    try:
        subprocess.run(["mount", "-t", "tmpfs", "-o", options, "tmpfs", str(where)], check=True,
                       capture_output=True)
    except (OSError, subprocess.CalledProcessError) as exc:
        pytest.skip(f"cannot mount a tmpfs here ({exc})")


def test_a_read_only_output_directory_is_refused(bar, tmp_path):
    where = tmp_path / "ro"
    _mount_tmpfs(where, "ro,size=1m")
    try:
        proc = parsph(["run", bar, "--out", where, "--quiet"])
        refused(proc, str(where), "Read-only file system")
    finally:
        subprocess.run(["umount", "-l", str(where)], check=False)


@pytest.mark.parametrize("ranks", [1, pytest.param(2, marks=pytest.mark.mpi)])
def test_a_full_disk_stops_the_run_with_one_message_and_readable_files(tmp_path, ranks):
    where = tmp_path / "small"
    _mount_tmpfs(where, "size=400k")
    try:
        proc = parsph(["run", RUNS / "patch_random.toml", "--out", where, "--quiet", "--set", "time.end=1e3",
                       "--set", "output.snapshot_interval=0.02", "--set", "output.checkpoint_every=40"],
                      ranks=ranks)
        refused(proc, "is full", "stopped at step", "output written so far is intact", code=1)
        if ranks > 1:
            assert "Segmentation" not in proc.stderr and "MPI_Abort" not in proc.stderr, proc.stderr
        with h5py.File(where / "history.h5", "r") as f:
            assert len(f["time"]) > 1 and np.all(np.isfinite(f["kinetic_energy"][()]))
        snaps = snapshots_of(where / "snapshots.h5")
        assert len(snaps) > 3
        import xml.etree.ElementTree as ET

        grids = ET.parse(where / "snapshots.xdmf").getroot().findall(".//Grid[@GridType='Uniform']")
        assert len(grids) == len(snaps)
    finally:
        subprocess.run(["umount", "-l", str(where)], check=False)


def test_restarted_and_stopped_runs_write_the_same_files_as_a_straight_run(bar, tmp_path):
    """History rows, snapshots and the XDMF index of a run continued from a checkpoint, and
    of a run stopped by the wall-clock limit and continued, equal those of a straight run."""
    common = [*HISTORY, "--set", "output.snapshot_interval=2e-4", "--set", "time.end=2e-3"]
    straight, split, stopped = tmp_path / "straight", tmp_path / "split", tmp_path / "stopped"
    # the three first runs one after another in one process (conftest.parsph_batch)
    procs = parsph_batch([["run", bar, "--out", straight, *common, "--quiet"],
                          ["run", bar, "--out", split, *common, "--set", "time.max_steps=37",
                           "--set", "output.checkpoint_every=10", "--quiet"],
                          ["run", bar, "--out", stopped, *common, "--set", "time.wall_limit=1e-9", "--quiet"]],
                         1, tmp_path / "batch")
    for proc in procs:
        assert proc.returncode == 0, proc.stderr
    run_ok([bar, "--out", split, *common, "--restart", "latest"])
    assert_same_run(straight, split)

    proc = procs[-1]
    assert "stopped by the wall-clock limit" in proc.stdout
    words = shlex.split(proc.stdout.split("continue with: ")[1].splitlines()[0])
    assert words[:2] == ["parsph", "run"] and "time.wall_limit=1e-9" in words  # the --set options kept
    words[words.index("time.wall_limit=1e-9")] = "time.wall_limit=0"
    cont = subprocess.run([sys.executable, "-m", "parsph", *words[1:], "--quiet"], cwd=ROOT, capture_output=True,
                          text=True, timeout=CEILING)
    assert cont.returncode == 0, cont.stderr
    assert_same_run(straight, stopped)


def test_the_continue_command_runs_as_printed(bar, tmp_path):
    out = tmp_path / "out"
    proc = run_ok([bar, "--out", out, "--set", "time.wall_limit=1e-9", "--set", "output.history_every=3",
                   "--set", "output.history_interval=0.0"])
    words = shlex.split(proc.stdout.split("continue with: ")[1].splitlines()[0])
    cont = subprocess.run([sys.executable, "-m", "parsph", *words[1:], "--quiet", "--set", "time.max_steps=30"],
                          cwd=ROOT, capture_output=True, text=True, timeout=CEILING)
    assert cont.returncode == 0, cont.stderr
    assert "stopped by" in cont.stdout  # the wall limit, kept as given, stops it again
    with h5py.File(out / "history.h5", "r") as f:
        assert np.all(np.diff(f["step"][()]) == 3)


def test_the_last_step_ends_exactly_at_time_end(bar, tmp_path):
    for end in ("1e-9", "3.3e-4"):
        out = tmp_path / end
        run_ok([bar, "--out", out, "--set", f"time.end={end}"])
        with h5py.File(out / "history.h5", "r") as f:
            assert f["time"][-1] == float(end)


def test_an_endless_run_is_warned_about(bar, tmp_path):
    proc = run_ok([bar, "--out", tmp_path / "out", "--set", "material.youngs_modulus=1e300",
                   "--set", "time.wall_limit=2"])
    assert "warning: this run would take about" in proc.stderr and "years" in proc.stderr, proc.stderr


def test_progress_counts_towards_max_steps_and_prints_long_times_readably(capsys):
    from parsph.progress import Progress, format_duration

    progress = Progress(end_time=1e3, max_steps=100, particles=10, interval=0.0, enabled=True)
    progress.update(0, 0.0, 1e-3, force=True)
    time.sleep(0.05)
    progress.update(50, 0.05, 1e-3, force=True)
    line = capsys.readouterr().out.strip().splitlines()[-1]
    assert " 50.0 %" in line, line
    assert format_duration(3725) == "1:02:05"
    assert format_duration(5e6) == "57.9 days"
    assert format_duration(1e150).endswith("years") and len(format_duration(1e150)) < 20


@pytest.mark.mpi
def test_two_ranks_refuse_a_directory_in_use(bar, tmp_path):
    out = tmp_path / "out"
    first = _start([bar, "--out", out, "--set", "time.end=1e3"])
    try:
        wait_for(lambda: (out / "history.h5").exists(), poll=0.1)
        proc = subprocess.run([mpiexec(), "-n", "2", sys.executable, "-m", "parsph", "run", str(bar), "--out",
                               str(out), "--quiet", "--overwrite"], cwd=ROOT, capture_output=True, text=True,
                              timeout=CEILING)
        refused(proc, "in use by another run")
    finally:
        os.killpg(first.pid, signal.SIGKILL)
        first.communicate()


@pytest.mark.timeout(CEILING)
def test_an_output_interval_far_below_the_step_fires_every_step_at_once():
    from parsph.io.outputs import Schedule

    every = Schedule(interval=1e-12, every=0)
    for step, t in enumerate((1.5e-7, 3.0e-7, 4.5e-3), start=1):
        assert every.due(t, step)
        assert t < every.next <= t + 1e-12 * (1 + 1e-9) + 1e-12 * t
