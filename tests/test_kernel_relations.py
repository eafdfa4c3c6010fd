"""Kernel relations per group of bodies (parsph.kernel_relation): bodies with their own
kernel ([bodies.kernel]), Hessian stabilisation eta [V eq. 17] or reference update schedule
[V §3.1] in one scene, each moving bit for bit as it does alone; the same on 1 and 3 ranks
and across a restart."""

from __future__ import annotations

import h5py
import numpy as np
import pytest

from conftest import assert_identical_outputs, parsph, parsph_by_ranks
from parsph.errors import InputError
from physics import scene_from, simulation

STEPS = 60

BLOCKS = {  # a steel-like and a rubber-like block, 10 mm apart, stretched by 1 % and released
    "steel": ("0.0", "0.1", 'model = "saint_venant_kirchhoff"\ndensity = 7800.0\nyoungs_modulus = 200.0e9\n'
                            'poisson_ratio = 0.3'),
    "rubber": ("0.11", "0.21", 'model = "neo_hookean"\ndensity = 1100.0\nyoungs_modulus = 0.3e9\n'
                               'poisson_ratio = 0.45'),
}


def blocks(bodies: dict, top: str = 'type = "cubic_spline"\nsupport = 2.0') -> str:
    """A 2D scene (text) of the named BLOCKS at a fixed step, each {name: (its formulation
    lines, its kernel lines)}; `top`: the [kernel] table's lines."""
    text = f'[scene]\nname = "blocks"\ndimension = 2\n[kernel]\n{top}\n[formulation]\ntype = "tlsph"\n'
    for name, (form, kernel) in bodies.items():
        lo, hi, material = BLOCKS[name]
        centre = 0.5 * (float(lo) + float(hi))
        text += (f'[[bodies]]\nname = "{name}"\n[[bodies.parts]]\nshape = "box"\nlower = [{lo}, 0.0]\n'
                 f'upper = [{hi}, 0.05]\nspacing = 0.005\n[bodies.material]\n{material}\n'
                 f'[bodies.formulation]\n{form}\n[bodies.kernel]\n{kernel}\n'
                 f'[groups.{name}_block]\nbox = {{ lower = [{lo}, 0.0], upper = [{hi}, 0.05] }}\n'
                 f'[[initial]]\ntype = "displacement_gradient"\ngroup = "{name}_block"\n'
                 f'gradient = [[0.01, 0.0], [0.0, 0.01]]\ncenter = [{centre}, 0.025]\n')
    return text + f"[time]\nend = 1.0\ndt = 2.0e-7\nmax_steps = {STEPS}\n[output]\nhistory_every = 10\n"


def stepped(text: str):
    sim = simulation(text)
    for _ in range(STEPS):
        sim.step()
    return sim


def assert_each_as_alone(both, alones: dict) -> None:
    """Each body of `both` has the displacements, velocities and deformation gradients of its
    run alone, bit for bit, and the same energies."""
    d_both = both.diagnostics()
    for body in both.state.bodies:
        alone = alones[body.name]
        rows = np.arange(body.lo, body.hi)
        assert len(rows) == alone.state.n_owned
        for name in ("displacement", "velocity", "deformation_gradient"):
            assert np.array_equal(both.quantity(name, rows), alone.quantity(name)), (body.name, name)
        d_alone = alone.diagnostics()
        for name in ("kinetic_energy", "strain_energy", "hourglass_energy"):
            assert d_both[f"{name}.{body.name}"] == d_alone[name], (body.name, name)


UPDATED = {"steel": ('type = "ulsph"\nupdate_every = 3\nhourglass = 20.0', ""),
           "rubber": ('type = "ulsph"\nupdate_every = 5\nhourglass = 20.0\nsearch_every = 2', "")}
KERNELS = {"steel": ("", ""), "rubber": ('type = "sph"', 'type = "wendland_c2"\nsupport = 2.4')}
HESSIAN = {"steel": ("hessian = 0.3", ""), "rubber": ('hessian = 0.6\nhessian_correction = "paper"', "")}


BY_STRAIN = {"steel": UPDATED["steel"], "rubber": ('type = "ulsph"\nupdate_strain = 3e-3\nhourglass = 20.0', "")}


@pytest.mark.parametrize("bodies", [UPDATED, BY_STRAIN], ids=["by_count", "by_count_and_strain"])
def test_updated_bodies_with_their_own_schedules_each_move_as_alone(bodies):
    """Two ulsph bodies updated every 3 and every 5 steps (the second searching at every
    other update), or every 3 steps and by a log strain of 3e-3 [V §3.1]: two relations,
    each updating on its own schedule, as often as its body alone and not as often as the
    other; each body bit for bit as alone."""
    both = stepped(blocks(bodies))
    alones = {name: stepped(blocks({name: bodies[name]})) for name in bodies}
    counts = [r.count for r in both.topology.relations]
    assert counts == [alones["steel"].topology.count, alones["rubber"].topology.count]
    assert counts[0] == STEPS // 3 and 0 < counts[1] != counts[0]
    lo, hi = both.state.bodies[1].lo, both.state.bodies[1].hi
    assert np.array_equal(both.state.Xr[lo:hi], alones["rubber"].state.Xr[: alones["rubber"].state.n_owned])
    assert_each_as_alone(both, alones)


def test_bodies_with_their_own_kernels_each_move_as_alone():
    """The rubber block with the Wendland C2 kernel and a wider support beside the steel
    block with the cubic spline: each as alone with its kernel as the scene's [kernel]; the
    rubber block's kernel makes a difference."""
    both = stepped(blocks(KERNELS))
    assert [r.kernel for r in both.topology.relations] == ["cubic_spline", "wendland_c2"]
    rubber = both.state.bodies[1]
    assert np.all(both.state.support[rubber.lo:rubber.hi] == 2.4 * 0.005)
    alones = {"steel": stepped(blocks({"steel": KERNELS["steel"]})),
              "rubber": stepped(blocks({"rubber": (KERNELS["rubber"][0], "")},
                                       top='type = "wendland_c2"\nsupport = 2.4'))}
    assert_each_as_alone(both, alones)
    spline = stepped(blocks({"rubber": (KERNELS["rubber"][0], "")}))
    assert not np.array_equal(spline.quantity("velocity"), alones["rubber"].quantity("velocity"))


def test_bodies_with_their_own_hessian_stabilisation_each_move_as_alone():
    """eta = 0.3 (kernel-weighted correction) on the steel block, 0.6 (the paper's) on the rubber
    block [V eq. 17, 21]: two relations; each body as alone."""
    both = stepped(blocks(HESSIAN))
    relations = both.topology.relations
    assert [(r.eta, r.weighted_hessian) for r in relations] == [(0.3, True), (0.6, False)]
    for r, body in zip(relations, both.state.bodies):  # each relation holds its body's stabilisation
        counts = np.diff(r.ref.ptr)
        assert counts[body.lo:body.hi].all() and not np.delete(counts, np.arange(body.lo, body.hi)).any()
        assert np.abs(r.ref.q).max() > 0
    assert_each_as_alone(both, {name: stepped(blocks({name: HESSIAN[name]})) for name in HESSIAN})


@pytest.mark.mpi
def test_relations_are_the_same_on_1_and_3_ranks_and_across_a_restart(tmp_path):
    """For each of the schedules, strain, kernels and hessian scenes: one rank straight
    through against two ranks to step 40 (between the updates of one relation, just after
    the other's) and three after the restart: the same bit for bit. The scenes' runs on one
    rank count go one after another in one MPI job (conftest.parsph_by_ranks): the straight
    and the stopped runs, then the restarts."""
    cases = {"schedules": UPDATED, "strain": BY_STRAIN, "kernels": KERNELS, "hessian": HESSIAN}
    stopped = ["--set", "time.max_steps=40", "--set", "output.checkpoint_every=40"]
    commands, restarts = [], []
    for name, bodies in cases.items():
        path = tmp_path / f"{name}.toml"
        path.write_text(blocks(bodies))
        one, split = tmp_path / name / "one", tmp_path / name / "split"
        commands += [(1, ["run", path, "--out", one, "--quiet"]),
                     (2, ["run", path, "--out", split, "--quiet", *stopped])]
        restarts.append((3, ["run", path, "--out", split, "--quiet", "--restart", "latest"]))
    procs = parsph_by_ranks(commands, tmp_path / "batch")
    procs += parsph_by_ranks(restarts, tmp_path / "batch_restarts")  # after the stopped runs
    for (_, argv), proc in zip(commands + restarts, procs):
        assert proc.returncode == 0, f"{argv}: {proc.stderr}"
    for name in cases:
        one, split = tmp_path / name / "one", tmp_path / name / "split"
        assert_identical_outputs(one, split)
        with h5py.File(one / "history.h5", "r") as f:
            assert f["step"][-1] == STEPS and np.isfinite(f["total_energy"][()]).all(), name


@pytest.mark.parametrize("key, message", [
    ("typo = 1.0", "unknown key 'bodies[1].kernel.typo'"),
    ("neighbours = 12", "unknown key 'bodies[1].kernel.neighbours'"),
    ('type = "gauss"', "bodies[1].kernel.type must be one of"),
])
def test_a_body_kernel_key_that_does_not_exist_is_refused(key, message, tmp_path):
    text = blocks({"steel": ("", ""), "rubber": ("", key)})
    with pytest.raises(InputError, match=message.replace("[", r"\[").replace("]", r"\]")):
        scene_from(text)
    path = tmp_path / "bad.toml"
    path.write_text(text)
    proc = parsph(["run", path, "--out", tmp_path / "out", "--quiet"])
    assert proc.returncode == 2 and message in proc.stderr and "Traceback" not in proc.stderr, proc.stderr
