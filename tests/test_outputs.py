"""Output files of a run: history, snapshots with a valid XDMF index, plots."""

from __future__ import annotations

import json
import tomllib
import xml.etree.ElementTree as ET

import h5py
import numpy as np
import pytest

from conftest import RUNS, parsph
from parsph import readouts
from parsph.api import build, load_scene
from parsph.errors import InputError
from parsph.io import history as history_module
from parsph.io import read_history, read_snapshots
from physics import simulation


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


BLOCK = """
[scene]
name = "block"
dimension = {dim}
[[geometry.parts]]
shape = "box"
lower = {lower}
upper = {upper}
spacing = 1.0
[kernel]
support = 2.5
[material]
model = "{model}"
density = 1.0
youngs_modulus = 1.0
poisson_ratio = 0.3
{extra}
[formulation]
hourglass = 0.0
[time]
end = 1.0
[[initial]]
type = "displacement_gradient"
group = "all"
gradient = {gradient}
"""


def block(dim: int, model: str, strain: float, extra: str = ""):
    """A 12^dim lattice of unit spacing under the uniform uniaxial strain u_x = strain x."""
    gradient = np.zeros((dim, dim))
    gradient[0, 0] = strain
    return simulation(BLOCK.format(dim=dim, lower=[0.0] * dim, upper=[12.0] * dim, model=model, extra=extra,
                                   gradient=gradient.tolist()))


def centre(sim) -> int:
    X = sim.quantity("reference_position")
    return int(np.argmin(np.linalg.norm(X - X.mean(axis=0), axis=1)))


@pytest.mark.parametrize("dim", [1, 2])
def test_von_mises_of_plane_and_uniaxial_strain_has_the_out_of_plane_stresses(dim):
    """Saint Venant-Kirchhoff (E = 1, nu = 0.3) under the uniaxial strain F = diag(1 + e, 1, 1):
    S_xx = (lambda + 2 mu) E_xx, S_yy = S_zz = lambda E_xx (the held directions carry stress),
    sigma = F S F^T / J, von Mises |sigma_xx - sigma_yy| (about 2 mu e), in 1D (uniaxial
    strain) as in 2D (plane strain)."""
    e = 1e-3
    lam, mu = 0.3 / (1.3 * 0.4), 1.0 / 2.6
    E = e + 0.5 * e * e
    expected = abs((1 + e) * (lam + 2 * mu) * E - lam * E / (1 + e))
    assert expected == pytest.approx(2 * mu * e, rel=5e-3)
    sim = block(dim, "saint_venant_kirchhoff", e)
    i = centre(sim)
    assert sim.quantity("von_mises", np.array([i]))[0] == pytest.approx(expected, rel=1e-9)
    full = readouts.cauchy_stress(sim, np.array([i]), full=True)[0]
    assert full[2, 2] == pytest.approx(lam * E / (1 + e), rel=1e-9)
    assert np.allclose(full[:dim, :dim], sim.quantity("cauchy_stress", np.array([i]))[0], rtol=0, atol=1e-15)


def test_von_mises_of_a_yielded_plane_strain_point_is_the_yield_stress():
    """J2 plasticity in plane strain (sigma_Y = 1e-3 E, no hardening), stretched to 10 times
    the yield strain: the yielded centre particle's Kirchhoff stress is on the yield surface,
    so J times the von Mises stress of its Cauchy stress is sigma_Y (with sigma_zz, which the
    plastic flow out of the plane sets)."""
    sim = block(2, "j2_plasticity", 1e-2, extra="yield_stress = 1.0e-3")
    sim.step()  # the committed state is that of a return from the stretched state
    i = centre(sim)
    assert sim.quantity("plastic_strain", np.array([i]))[0] > 0
    kirchhoff = sim.quantity("J", np.array([i]))[0] * sim.quantity("von_mises", np.array([i]))[0]
    assert kirchhoff == pytest.approx(1e-3, rel=1e-6)


def test_a_snapshot_with_a_value_that_is_not_finite_is_refused_before_it_is_written(tmp_path):
    """The writer checks every field of every particle first: the file keeps the snapshots
    written before, whole, and gains nothing of the refused one."""
    from mpi4py import MPI

    from parsph.errors import ParsphError
    from parsph.io.snapshots import SnapshotWriter

    sim = block(2, "saint_venant_kirchhoff", 1e-3)
    writer = SnapshotWriter(str(tmp_path), "{}", MPI.COMM_SELF)
    writer.write(sim, ["position", "velocity"])
    before = (tmp_path / "snapshots.h5").read_bytes(), (tmp_path / "snapshots.xdmf").read_text()
    sim.state.v[7, 1] = np.inf
    sim.running.step += 1
    message = rf"the snapshot at step 1, .*velocity of particle {sim.state.gid[7]} is not finite"
    with pytest.raises(ParsphError, match=message):
        writer.write(sim, ["position", "velocity"])
    assert ((tmp_path / "snapshots.h5").read_bytes(), (tmp_path / "snapshots.xdmf").read_text()) == before


def test_history_rows_wait_in_memory_and_reach_the_file_at_a_write_and_at_the_close(tmp_path, monkeypatch):
    """Rows are written in blocks (at least every WRITE_SECONDS, before every checkpoint,
    at the end): between writes the file stays readable with the rows written so far."""
    monkeypatch.setattr(history_module, "WRITE_SECONDS", 3600.0)
    path = tmp_path / "history.h5"
    writer = history_module.HistoryWriter(str(path), "{}", {})
    for step in range(3):
        writer.append({"time": 0.1 * step, "step": float(step)})
    writer.write()
    writer.append({"time": 0.3, "step": 3.0})
    with h5py.File(path, "r") as f:  # another reader while the run goes on
        assert list(f["step"][()]) == [0.0, 1.0, 2.0]
    writer.close()
    assert list(read_history(path)["step"]) == [0.0, 1.0, 2.0, 3.0]


def test_the_python_api_steps_to_the_state_a_run_wrote_and_reads_it_back(bar_run, tmp_path):
    """parsph.api builds bar_run's scene (from its file, its text or its table: the same
    resolved scene) on one rank and steps it to the end; parsph.io reads the 2-rank run's
    snapshots and history: the same positions and energies bit for bit, in global-id order."""
    overrides = ["time.end=4e-4", "output.snapshot_interval=1e-4"]
    scene = load_scene(RUNS / "bar1d.toml", overrides)
    text = (RUNS / "bar1d.toml").read_text()
    assert load_scene(text, overrides) == scene == load_scene(tomllib.loads(text), overrides)
    sim = build(scene)
    while sim.t < 4e-4:
        sim.step(4e-4)
    snapshots = read_snapshots(bar_run)
    assert [s.step for s in snapshots] == sorted({s.step for s in snapshots}) and snapshots[-1].time == sim.t
    last = read_snapshots(bar_run, ["gid", "position"], which=-1)[0]
    n = sim.state.n_owned
    assert np.array_equal(last["gid"], sim.state.gid[:n])
    assert np.array_equal(last["position"][:, :1], sim.quantity("position"))
    h = read_history(bar_run)
    assert h["step"][-1] == sim.step_count and h["kinetic_energy"][-1] == sim.diagnostics()["kinetic_energy"]
    with pytest.raises(InputError, match="no field 'stress_xx' in snapshot step_"):
        read_snapshots(bar_run, ["position", "stress_xx"])
    with pytest.raises(InputError, match="history.h5 does not exist"):
        read_history(tmp_path)
