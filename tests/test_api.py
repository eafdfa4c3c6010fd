"""The Python interface refuses bad calls with an InputError that names the problem: a file
of the other kind or a damaged one, a snapshot index out of range, an unknown quantity,
and a scene dict that a scene file with the same content would not pass."""

from __future__ import annotations

import math
import shutil

import h5py
import pytest

from conftest import RUNS, parsph
from parsph.api import build, load_scene
from parsph.errors import InputError
from parsph.io import read_history, read_snapshots
from physics import simulation


@pytest.fixture(scope="module")
def bar_run(tmp_path_factory):
    out = tmp_path_factory.mktemp("bar")
    proc = parsph(["run", RUNS / "bar1d.toml", "--out", out, "--quiet", "--set", "time.end=2e-4",
                   "--set", "output.snapshot_interval=1e-4"])
    assert proc.returncode == 0, proc.stderr
    return out


def test_a_file_of_the_other_kind_is_refused(bar_run):
    with pytest.raises(InputError, match="snapshots.h5 is not a run's history: it holds snapshots"):
        read_history(bar_run / "snapshots.h5")
    with pytest.raises(InputError, match="history.h5 is not a run's snapshots: it holds the series"):
        read_snapshots(bar_run / "history.h5")
    with pytest.raises(InputError, match="bar1d.toml cannot be read: it is not an HDF5 file"):
        read_history(RUNS / "bar1d.toml")


def test_a_damaged_history_is_refused(bar_run, tmp_path):
    truncated = tmp_path / "truncated.h5"
    data = (bar_run / "history.h5").read_bytes()
    truncated.write_bytes(data[: len(data) // 2])
    with pytest.raises(InputError, match="truncated.h5 cannot be read: .* damaged or truncated"):
        read_history(truncated)
    uneven = tmp_path / "uneven.h5"
    shutil.copy(bar_run / "history.h5", uneven)
    with h5py.File(uneven, "a") as f:
        rows = len(f["time"])
        f["kinetic_energy"].resize((rows - 1,))
    with pytest.raises(InputError, match=rf"uneven.h5 is damaged: .*shape \({rows},\); kinetic_energy \({rows - 1},\)"):
        read_history(uneven)


@pytest.mark.parametrize(("which", "message"), [
    (99, r"which = 99: the run has 3 snapshot\(s\), so an index must be in \[-3, 2\]"),
    ([0, -4], r"which = \[0, -4\]: the run has 3 snapshot"),
    ("last", r"which = 'last': give an index, a slice or a list of indices"),
])
def test_a_snapshot_index_out_of_range_is_refused(bar_run, which, message):
    assert [s.step for s in read_snapshots(bar_run, ["position"], which=[0, -1])] == [0, read_snapshots(bar_run)[-1].step]
    with pytest.raises(InputError, match=message):
        read_snapshots(bar_run, which=which)


def test_an_unknown_quantity_is_refused_with_the_known_names():
    sim = simulation("bar1d", ["time.end=1e-5"])
    with pytest.raises(InputError, match=r"unknown quantity 'positon' \(did you mean 'position'\?\); the known "
                                         r"ones: .*displacement.*velocity"):
        sim.quantity("positon")


def test_build_validates_the_scene_it_is_given():
    scene = load_scene(RUNS / "bars_impact.toml")
    assert build(scene).interactions.contact is not None  # a resolved scene passes unchanged, as does its table
    assert build(scene.as_dict()).interactions.contact is not None
    contact = scene.as_dict()
    contact["contact"][0]["radius"] = math.nan
    with pytest.raises(InputError, match=r"contact\[0\].radius must be finite, got nan"):
        build(contact)
    bar = load_scene(RUNS / "bar1d.toml").as_dict()
    bar["material"]["density"] = -7850.0
    with pytest.raises(InputError, match=r"material.density must be > 0 \(got -7850.0\)"):
        build(bar)
    with pytest.raises(InputError, match="build takes a scene"):
        build(str(RUNS / "bar1d.toml"))
