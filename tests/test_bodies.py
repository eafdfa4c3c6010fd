"""Several bodies in one scene ([[bodies]]): each with its material and formulation, no
kernel pairs between bodies, energies per body and in total, the same on any rank count."""

from __future__ import annotations

import copy
import tomllib

import numpy as np
import pytest

from conftest import RUNS, assert_it_happened, assert_same_on_ranks
from parsph import config
from parsph.build import build_local
from parsph.errors import InputError
from parsph.simulation import Simulation
from mpi4py import MPI


def _raw():
    with open(RUNS / "two_blocks.toml", "rb") as fh:
        return tomllib.load(fh)


def _sim(raw, steps=0):
    scene = config.validate(raw)
    sim = Simulation(scene, build_local(scene, MPI.COMM_SELF), MPI.COMM_SELF)
    for _ in range(steps):
        sim.step()
    return sim


@pytest.mark.parametrize("hessian", [0.0, 0.3])
def test_a_body_moves_as_it_would_alone(hessian):
    """The steel block of two_blocks follows, bit for bit, the run of the steel block alone
    (its step limits both runs' time step): the other body does not touch it; also with
    Hessian stabilisation [V eq. 17] on the steel block only."""
    raw = _raw()
    raw["bodies"][0]["formulation"] = {"hessian": hessian}
    both = _sim(copy.deepcopy(raw), steps=60)
    alone_raw = copy.deepcopy(raw)
    del alone_raw["bodies"][1], alone_raw["initial"][1], alone_raw["groups"]["right_block"]
    alone = _sim(alone_raw, steps=60)
    steel = both.state.bodies[0]
    assert (steel.lo, steel.hi) == (0, alone.state.n_owned)
    assert both.t == alone.t
    for name in ("displacement", "velocity"):
        assert np.array_equal(both.quantity(name)[:alone.state.n_owned], alone.quantity(name)), name
    d_both, d_alone = both.diagnostics(), alone.diagnostics()
    for name in ("kinetic_energy", "strain_energy", "hourglass_energy", "total_energy"):
        assert d_both[f"{name}.steel"] == d_alone[name]
    # the totals are the bodies' sums
    for name in ("kinetic_energy", "strain_energy", "total_energy"):
        parts = d_both[f"{name}.steel"] + d_both[f"{name}.rubber"]
        assert d_both[name] == pytest.approx(parts, rel=1e-14)
    assert d_both["kinetic_energy.rubber"] > 0 and d_both["strain_energy.rubber"] > 0


@pytest.mark.parametrize("updated, updates", [({"type": "ulsph", "update_every": 3, "hourglass": 20.0}, 20),
                                              ({"type": "rlm", "kernel": "eulerian", "search_every": 7}, 60)],
                         ids=["ulsph", "eulerian"])
def test_an_updated_body_moves_beside_a_total_lagrangian_one_as_each_alone(updated, updates):
    """The rubber block of two_blocks in an updated reference (ulsph updated every 3 steps,
    or RLM with the Eulerian kernel) beside the steel block in its initial one, at a fixed
    step: the rubber block follows its run alone bit for bit through every update; the
    steel block keeps its reference and follows its run alone to round-off (its reference
    data is built by the updated reference's compiled builder, as the rubber block's)."""
    raw = _raw()
    raw["time"]["dt"] = 2e-7
    raw["bodies"][1]["formulation"] = updated
    both = _sim(copy.deepcopy(raw), steps=60)
    assert both.topology.count == updates
    steel_raw, rubber_raw = copy.deepcopy(raw), copy.deepcopy(raw)
    del steel_raw["bodies"][1], steel_raw["initial"][1], steel_raw["groups"]["right_block"]
    del rubber_raw["bodies"][0], rubber_raw["initial"][0], rubber_raw["groups"]["left_block"]
    steel, rubber = _sim(steel_raw, steps=60), _sim(rubber_raw, steps=60)
    lo, hi = both.state.bodies[1].lo, both.state.bodies[1].hi
    n = rubber.state.n_owned
    assert hi - lo == n and both.state.bodies[0].hi == steel.state.n_owned
    for name in ("displacement", "velocity", "deformation_gradient"):
        assert np.array_equal(both.quantity(name, np.arange(lo, hi)), rubber.quantity(name)), name
    assert np.array_equal(both.state.Xr[lo:hi], rubber.state.Xr[:n]), "Xr"
    assert np.array_equal(both.state.Xr[:lo], both.quantity("reference_position")[:lo])  # the steel block's reference stays
    u, v = steel.quantity("displacement"), steel.quantity("velocity")
    scale = np.abs(u).max()
    assert np.abs(both.quantity("displacement")[:lo] - u[:lo]).max() < 1e-10 * scale
    assert np.abs(both.quantity("velocity")[:lo] - v[:lo]).max() < 1e-8 * np.abs(v[:lo]).max()
    d_both, d_rubber = both.diagnostics(), rubber.diagnostics()
    for name in ("kinetic_energy", "strain_energy", "hourglass_energy"):
        assert d_both[f"{name}.rubber"] == d_rubber[name]


def test_bodies_within_a_kernel_support_are_not_neighbours():
    raw = _raw()
    raw["bodies"][1]["parts"][0]["lower"][0] = 0.1  # touching: one spacing between the lattices
    raw["bodies"][1]["parts"][0]["upper"][0] = 0.2
    sim = _sim(raw)
    rows = np.repeat(np.arange(sim.state.n_owned), np.diff(sim.topology.relations[0].ref.ptr))
    assert len(rows) and np.array_equal(sim.state.body[rows], sim.state.body[sim.topology.relations[0].ref.idx])
    near = np.abs(sim.state.X[:, 0] - 0.1) < 0.01  # both bodies' particles next to the joint
    assert set(sim.state.body[near]) == {0, 1}


def test_each_body_has_its_material_and_formulation():
    sim = _sim(_raw())
    steel, rubber = sim.state.bodies
    assert (steel.law.name, rubber.law.name) == ("saint_venant_kirchhoff", "neo_hookean")
    assert (steel.formulation.type, rubber.formulation.type) == ("tlsph", "sph")
    assert steel.formulation.alpha == 50.0 and rubber.formulation.alpha == 0.0
    assert np.all(sim.state.youngs[sim.state.body == 0] == 200e9) and np.all(sim.state.youngs[sim.state.body == 1] == 0.3e9)
    assert sim.quantity("mass")[sim.quantity("body") == 1].max() == pytest.approx(1100.0 * 0.005 ** 2)


@pytest.mark.parametrize("change, message", [
    (lambda raw: raw.update(material={"model": "neo_hookean", "density": 1.0}), "remove the top-level [material]"),
    (lambda raw: raw["bodies"][1].update(name="steel"), "bodies[1].name must be a distinct identifier"),
    (lambda raw: [raw["bodies"][0].update(formulation={"type": "ulsph", "update_every": 3}),
                  raw["bodies"][1]["formulation"].update(kernel="eulerian")],
     "all type = 'ulsph' or all kernel = 'eulerian'"),
    (lambda raw: raw["bodies"][0]["material"].pop("density"), "missing required key 'bodies[0].material.density'"),
    (lambda raw: raw["bodies"][1]["material"].update(shear_modulus=1.0),
     "bodies[1].material.shear_modulus does not apply"),
    (lambda raw: raw.update(geometry={"parts": [{"shape": "box"}]}), "remove geometry.parts"),
])
def test_bad_bodies_are_refused_naming_the_key(change, message):
    raw = copy.deepcopy(_raw())
    change(raw)
    with pytest.raises(InputError, match=message.replace("[", r"\[").replace("]", r"\]").replace(".", r"\.")):
        config.validate(raw)


@pytest.mark.mpi
@pytest.mark.parametrize("rubber", [[], ["--set", 'bodies.1.formulation.type="efg"',
                                         "--set", 'bodies.1.formulation.integration="cells"']],
                         ids=["sph", "efg-cells"])
def test_two_bodies_on_one_and_two_ranks_bit_for_bit(rubber, tmp_path):
    """Also with the second body's Gauss points (EFG with cells), which a rank holding none
    of them must handle."""
    outs = assert_same_on_ranks(RUNS / "two_blocks.toml", ["--set", "time.max_steps=100", *rubber], tmp_path,
                                ranks=(1, 2))
    assert_it_happened(outs[-1], ranks=2)
