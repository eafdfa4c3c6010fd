"""Symmetry planes by mirror images (parallel.mirrors): a quarter of a symmetric body with two
planes moves as the whole body does, in the total- and in the updated-Lagrangian formulation,
with nodal EFG, with neighbour lists kept between searches, and in contact with another body
(the images take part in contact)."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial import cKDTree

from parsph.errors import InputError
from physics import run_until, simulation

SPACING = 2.5e-4


def pressed_block(quarter: bool, formulation: str) -> str:
    """A neo-Hookean block 8 mm x 4 mm pressed from above and below by rounded tools 4 mm
    wide at 1 m/s: the quarter x, y > 0 with two symmetry planes, or the whole block."""
    lower = "[0.0, 0.0]" if quarter else "[-0.004, -0.002]"
    rest = """[[symmetry]]
axis = 0
position = 0.0
[[symmetry]]
axis = 1
position = 0.0
""" if quarter else f"""[[tools]]
lower = [-0.002, -0.01]
upper = [0.002, {-0.002 + SPACING / 2}]
radius = 5.0e-4
velocity = [0.0, 1.0]
"""
    return f"""
[scene]
name = "pressed"
dimension = 2
[[geometry.parts]]
shape = "box"
lower = {lower}
upper = [0.004, 0.002]
spacing = {SPACING}
[kernel]
type = "wendland_c2"
support = 2.2
[material]
model = "neo_hookean_nearly_incompressible"
density = 1100.0
shear_modulus = 0.3571e6
bulk_modulus = 1.67e6
[formulation]
{formulation}
[time]
end = 1.5e-4
dt = 1.0e-6
[[tools]]
lower = [-0.002, {0.002 - SPACING / 2}]
upper = [0.002, 0.01]
radius = 5.0e-4
velocity = [0.0, -1.0]
{rest}"""


@pytest.mark.parametrize("formulation", [
    'type = "tlsph"\nhourglass = 50.0',
    'type = "ulsph"\nupdate_every = 10\nhourglass = 50.0',
    'type = "efg"\nkernel = "eulerian"',  # the MLS row data of the images reflected (kernels.shape)
])
def test_quarter_with_two_planes_moves_as_the_whole_block(formulation):
    quarter = simulation(pressed_block(True, formulation))
    whole = simulation(pressed_block(False, formulation))
    n = quarter.state.n_owned
    assert whole.state.n_owned == 4 * n
    gap, match = cKDTree(whole.quantity("reference_position")).query(quarter.quantity("reference_position"))
    assert gap.max() < 1e-15
    for _ in range(150):
        quarter.step()
        whole.step()
    if quarter.state.updated and not quarter.state.eulerian:
        assert quarter.topology.count == whole.topology.count == 15
    scale = np.abs(whole.quantity("displacement")).max()
    assert scale > 1e-4  # the tools went 0.15 mm deep
    assert np.abs(quarter.quantity("displacement") - whole.quantity("displacement", match)).max() < 1e-10 * scale
    assert np.abs(quarter.quantity("velocity") - whole.quantity("velocity", match)).max() < 1e-8
    force = quarter.diagnostics()["tool0_force_y"]
    assert force < -1.0  # measured -27 N per metre of thickness: half of the whole block's top tool
    assert force == pytest.approx(0.5 * whole.diagnostics()["tool0_force_y"], rel=1e-9)


@pytest.mark.parametrize("planes, message", [
    ("axis = 0\nposition = 0.002", r"symmetry\[0\].*must bound the body"),
    ("axis = 2\nposition = 0.0", r"symmetry\[0\].axis = 2 must be in \[0, 1\]"),
    ("axis = 0\nposition = 0.0\n[[symmetry]]\naxis = 0\nposition = 0.004", r"symmetry\[1\]: a second"),
    ("axis = 0\nside = 1", r"unknown key 'symmetry\[0\].side'"),
])
def test_bad_symmetry_planes_are_refused(planes, message):
    text = pressed_block(False, 'type = "tlsph"').replace("[[tools]]", f"[[symmetry]]\n{planes}\n[[tools]]", 1)
    with pytest.raises(InputError, match=message):
        simulation(text)


def test_symmetry_planes_with_hessian_stabilisation_are_refused():
    """Mirror images would continue the body with reflected values, but the Hessian term is
    not reflection-symmetric (measured: the punch quarter with mirror images and eta = 1.4
    inverts a particle next to the plane y = 0 at 17 % compression; the whole block, and
    the quarter with fixed normal components, reach 50 %)."""
    with pytest.raises(InputError, match="not symmetric under reflection"):
        simulation(pressed_block(True, 'type = "tlsph"\nhessian = 0.3'))


PLATES_APART = ["bc.1.type=velocity", "bc.1.value=[0.0, 5.0]", "bc.0.value=[0.0, -5.0]"]  # both at 5 m/s


def test_quarter_in_contact_with_its_plate_moves_as_the_whole_block_between_two_plates():
    """runs/punch_hertz_quarter.toml against runs/punch_hertz.toml with both plates moving at
    5 m/s, at 15 rows (0.2 mm): the block's and the plate's particles near the plane x = 3 mm
    touch the mirror images of the other body's, and the quarter's particles (its middle row
    on the plane y = 1.5 mm, held vertically) move as the whole block's to round-off; the
    plate's contact force is half the whole model's, and the energies a quarter of the
    whole's: the middle row counts by its share (half) in the balance, which closes. Both at
    the whole's step: each model's step factor is its own force operator's (the whole's top
    mode need not be symmetric about the planes)."""
    dt = float(simulation("punch_hertz", ["parameters.spacing=2e-4", *PLATES_APART]).dt)
    quarter = simulation("punch_hertz_quarter", ["parameters.spacing=2e-4", f"time.dt={dt!r}"])
    whole = simulation("punch_hertz", ["parameters.spacing=2e-4", *PLATES_APART, f"time.dt={dt!r}"])
    gap, match = cKDTree(whole.quantity("reference_position")).query(quarter.quantity("reference_position"))
    assert gap.max() < 1e-15
    run_until(quarter, 1.5e-5, every=100)
    run_until(whole, 1.5e-5, every=100)
    scale = np.abs(whole.quantity("displacement")).max()
    assert scale > 5e-5  # the plates went 0.15 mm deep together
    assert np.abs(quarter.quantity("displacement") - whole.quantity("displacement", match)).max() < 1e-9 * scale
    rows = quarter.diagnostics()
    whole_rows = whole.diagnostics()
    force = rows["contact_force_y.block.top"]
    assert force < -1e4  # the plate presses on the block
    assert force == pytest.approx(0.5 * whole_rows["contact_force_y.block.top"], rel=1e-8)
    for key in ("kinetic_energy", "strain_energy", "total_energy"):
        assert rows[key] > 0.0 and rows[key] == pytest.approx(0.25 * whole_rows[key], rel=1e-7), key


@pytest.mark.mpi
def test_quarter_in_contact_is_the_same_on_1_and_3_ranks_and_across_a_restart(tmp_path):
    """runs/punch_hertz_quarter.toml at 0.12 mm, 600 steps (the plate presses from the start):
    the same history and final state bit for bit on 1 and 3 ranks, and a run checkpointed
    on 2 ranks, restarted on 3, continues exactly; the plate's contact force is not zero."""
    from conftest import RUNS, assert_identical_outputs, assert_runs_by_ranks
    from parsph.io import read_history

    scene = RUNS / "punch_hertz_quarter.toml"
    coarse = ["--set", "parameters.spacing=1.2e-4", "--set", "time.max_steps=600",
              "--set", "output.history_interval=0", "--set", "output.history_every=50"]
    one, three, split = tmp_path / "quarter" / "ranks_1", tmp_path / "quarter" / "ranks_3", tmp_path / "split"
    # three MPI jobs (conftest.parsph_by_ranks): one rank; two ranks; three ranks straight and restarted
    assert_runs_by_ranks([(1, ["run", scene, "--out", one, "--quiet", *coarse]),
                          (2, ["run", scene, "--out", split, "--quiet", *coarse, "--set", "time.max_steps=300",
                               "--set", "output.checkpoint_every=300"])], tmp_path / "batch")
    assert_runs_by_ranks([(3, ["run", scene, "--out", three, "--quiet", *coarse]),
                          (3, ["run", scene, "--out", split, "--quiet", *coarse, "--restart", "latest"])],
                         tmp_path / "batch_restart")
    assert_identical_outputs(one, three)
    assert_identical_outputs(one, split)
    force = read_history(tmp_path / "quarter" / "ranks_1")["contact_force_y.block.top"]
    assert force[-1] < -1e4


KEPT = ['type = "ulsph"\nupdate_every = 1\nhourglass = 50.0', 'type = "sph"\nkernel = "eulerian"',
        'type = "efg"\nkernel = "eulerian"']


@pytest.mark.parametrize("formulation", KEPT)
def test_quarter_with_kept_lists_moves_as_with_a_search_at_every_update(formulation):
    """The pressed quarter in the updated reference at every step, or with the Eulerian
    kernel: neighbour lists and mirror images searched with a skin at most every 30 updates
    (images within the support plus the skin of a plane, refreshed reflected in between) give
    the same positions and velocities, bit for bit, as a search at every update."""
    runs = []
    for every in (1, 30):
        sim = simulation(pressed_block(True, f"{formulation}\nsearch_every = {every}"))
        for _ in range(80):
            sim.step()
        runs.append((sim.quantity("position"), sim.quantity("velocity"), sim.topology.relations[0].rule.searches))
    assert runs[0][2] == 80 and runs[1][2] < 10  # the lists were kept between searches
    assert np.array_equal(runs[0][0], runs[1][0]) and np.array_equal(runs[0][1], runs[1][1])


@pytest.mark.mpi
def test_quarter_with_kept_lists_is_the_same_on_1_and_3_ranks(tmp_path):
    """The same, 80 steps as runs, for each of KEPT: searching at every update on one rank
    and keeping the lists for up to 30 updates on three give the same history and final
    state bit for bit. The formulations' runs on one rank count go one after another in one
    MPI job (conftest.parsph_by_ranks)."""
    from conftest import assert_identical_outputs, parsph_by_ranks

    commands, outs = [], []
    for k, formulation in enumerate(KEPT):
        outs.append([])
        for every, ranks in ((1, 1), (30, 3)):
            scene = tmp_path / f"kept_{k}_{every}.toml"
            scene.write_text(pressed_block(True, f"{formulation}\nsearch_every = {every}")
                             + "[output]\nhistory_every = 20\n")
            outs[-1].append(tmp_path / f"out_{k}_{every}")
            commands.append((ranks, ["run", scene, "--out", outs[-1][-1], "--quiet", "--set", "time.max_steps=80"]))
    for (_, argv), proc in zip(commands, parsph_by_ranks(commands, tmp_path / "batch")):
        assert proc.returncode == 0, f"{argv}: {proc.stderr}"
    for pair in outs:
        assert_identical_outputs(*pair)
