"""Output files of a run: history, snapshots with a valid XDMF index, plots."""

from __future__ import annotations

import json
import xml.etree.ElementTree as ET

import h5py
import numpy as np
import pytest

from conftest import RUNS, parsph


@pytest.fixture(scope="module")
def bar_run(tmp_path_factory):
    out = tmp_path_factory.mktemp("bar")
    proc = parsph(["run", RUNS / "bar1d.toml", "--out", out, "--quiet", "--set", "time.end=4e-4",
                   "--set", "output.snapshot_interval=1e-4"], ranks=2)
    assert proc.returncode == 0, proc.stderr
    return out


def test_history_has_diagnostics_probes_units_and_the_scene(bar_run):
    with h5py.File(bar_run / "history.h5", "r") as f:
        t = f["time"][()]
        assert t[0] == 0.0 and t[-1] >= 4e-4 and np.all(np.diff(t) > 0)
        for name in ("kinetic_energy", "strain_energy", "total_energy", "momentum_x", "disorder",
                     "tip_displacement", "reaction_A"):
            assert len(f[name]) == len(t) and np.all(np.isfinite(f[name][()]))
        assert f["tip_displacement"].attrs["units"] == "m"
        assert f["reaction_A"].attrs["units"] == "N"
        scene = json.loads(f.attrs["scene"])
    assert scene["scene"]["name"] == "bar1d"
    assert scene["formulation"]["force_form"] == "pair"  # defaults are filled in
    assert json.loads((bar_run / "scene.json").read_text()) == scene


def test_xdmf_points_at_every_snapshot_dataset(bar_run):
    root = ET.parse(bar_run / "snapshots.xdmf").getroot()
    grids = root.findall(".//Grid[@GridType='Uniform']")
    assert len(grids) == 5  # t = 0, 1e-4, ..., 4e-4
    with h5py.File(bar_run / "snapshots.h5", "r") as f:
        for grid in grids:
            n = int(grid.find("Topology").get("NumberOfElements"))
            assert n == 40
            for item in grid.iter("DataItem"):
                file, path = item.text.strip().split(":")
                assert file == "snapshots.h5"
                shape = tuple(int(s) for s in item.get("Dimensions").split())
                assert f[path].shape == shape
        times = [float(g.find("Time").get("Value")) for g in grids]
        assert times == sorted(times)
        last = sorted(k for k in f if k.startswith("step_"))[-1]
        assert sorted(np.unique(f[last]["rank"][()])) == [0, 1]


def test_plot_history_and_snapshots(bar_run):
    for target, names in (("history.h5", ["tip_displacement"]), ("snapshots.h5", ["velocity"])):
        out = bar_run / f"{target}.png"
        proc = parsph(["plot", bar_run / target, *names, "-o", out])
        assert proc.returncode == 0, proc.stderr
        assert out.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    proc = parsph(["plot", bar_run / "history.h5", "no_such_series"])
    assert proc.returncode == 2 and "no_such_series" in proc.stderr


def test_every_history_series_has_units_and_plots_put_one_unit_per_panel(bar_run):
    from parsph.io.history import read_units
    from parsph.io.plots import by_unit

    units = read_units(bar_run / "history.h5")
    assert all(units.values()), {k: u for k, u in units.items() if not u}
    assert units["momentum_x"] == "kg m/s" and units["kinetic_energy"] == "J" and units["dt"] == "s"
    names = ["tip_displacement", "kinetic_energy", "strain_energy", "reaction_A"]
    assert by_unit(names, units) == {"m": ["tip_displacement"], "J": ["kinetic_energy", "strain_energy"],
                                     "N": ["reaction_A"]}
    out = bar_run / "mixed.png"
    proc = parsph(["plot", bar_run / "history.h5", *names, "-o", out])
    assert proc.returncode == 0, proc.stderr
    assert out.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
