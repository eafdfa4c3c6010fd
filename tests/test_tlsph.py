"""Total-Lagrangian SPH: consistency, invariance and conservation [G §2-3], [V §2]."""

from __future__ import annotations

import inspect

import numpy as np
import pytest

from parsph import readouts
from parsph.profile import Recorder, python_sources
from physics import block_2d, elastic_constants, run_until, simulation

MODELS = ["saint_venant_kirchhoff", "neo_hookean", "neo_hookean_nearly_incompressible", "mooney_rivlin"]


def random_set_2d(hourglass=0.0, model="saint_venant_kirchhoff"):
    return block_2d(model=model, hourglass=hourglass).replace(
        'shape = "box"\nlower = [0.0, 0.0]\nupper = [1.0, 0.6]\nspacing = 0.1',
        'shape = "random_patch"\nlower = [0.0, 0.0]\nupper = [1.0, 1.0]\ncount = 300\nseed = 3',
    ).replace("support = 2.5", "neighbours = 14")


CUBE_3D = """
[scene]
name = "cube"
dimension = 3
[[geometry.parts]]
shape = "box"
lower = [0.0, 0.0, 0.0]
upper = [0.5, 0.4, 0.3]
spacing = 0.1
[kernel]
type = "cubic_spline"
support = 2.2
[material]
model = "MODEL"
density = 1000.0
ELASTIC
[formulation]
hourglass = 50.0
[time]
end = 1.0
"""


def cube(model):
    return CUBE_3D.replace("MODEL", model).replace("ELASTIC", elastic_constants(model))


def deform(sim, H):
    """Impose u = H X on every particle and evaluate the forces."""
    sim.state.u[:] = sim.state.X @ np.asarray(H).T
    sim.compute_forces()


@pytest.mark.parametrize("scene", ["random2d", "lattice3d"])
def test_affine_displacement_gives_exact_F_and_uniform_stress(scene):
    sim = simulation(random_set_2d() if scene == "random2d" else cube("saint_venant_kirchhoff"))
    d = sim.state.dim
    rng = np.random.default_rng(0)
    H = 0.05 * rng.standard_normal((d, d))
    deform(sim, H)
    n = sim.state.n_owned
    assert np.abs(sim.quantity("deformation_gradient") - (np.eye(d) + H)).max() < 1e-13
    P = sim.state.VP[:n] / sim.quantity("volume")[:, None, None]
    assert np.abs(P - P[0]).max() <= 1e-12 * np.abs(P[0]).max()


def test_uniform_stress_gives_zero_force_in_the_interior_of_a_lattice():
    sim = simulation(block_2d().replace("upper = [1.0, 0.6]", "upper = [1.6, 1.6]"))
    deform(sim, [[0.02, 0.01], [0.0, -0.01]])
    X = sim.quantity("reference_position")
    # two kernel radii (2 x 0.25) from the boundary: neither i nor its neighbours see it
    interior = np.all((X > 0.5) & (X < 1.1), axis=1)
    force = sim.quantity("force")
    scale = np.abs(force).max()
    assert interior.sum() >= 16
    assert np.abs(force[interior]).max() < 1e-12 * scale
    # the boundary carries the traction of the uniform stress
    assert np.abs(force[~interior]).max() > 1e-3 * scale


@pytest.mark.parametrize("model", MODELS)
@pytest.mark.parametrize("dim", [2, 3])
def test_rigid_rotation_by_90_degrees_gives_no_strain_or_stress(model, dim):
    sim = simulation(block_2d(model=model, hourglass=50.0) if dim == 2 else cube(model))
    if dim == 2:
        R = np.array([[0.0, -1.0], [1.0, 0.0]])
    else:
        R = np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]]) @ np.array(
            [[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]])
    deform(sim, R - np.eye(dim))
    n = sim.state.n_owned
    assert np.abs(sim.quantity("deformation_gradient") - R).max() < 1e-13
    assert np.abs(sim.state.VP[:n]).max() < 1e-6  # stress [Pa] x volume, moduli ~1e6 Pa
    assert np.abs(sim.quantity("force")).max() < 1e-6
    assert abs(sim.ledger.local(sim, "strain")) < 1e-12 * 1e6 * sim.quantity("volume").sum()  # round-off of mu V
    assert np.abs(readouts.disorder(sim)).max() < 1e-13


@pytest.mark.parametrize("form", ["pair", "virtual_work"])
@pytest.mark.parametrize("hourglass", [("0", "variational"), ("50", "paper"), ("50", "variational")])
def test_linear_momentum_is_conserved_to_round_off(form, hourglass):
    alpha, hg_form = hourglass
    sim = simulation(random_set_2d(hourglass=float(alpha)),
                     [f'formulation.force_form="{form}"', f'formulation.hourglass_form="{hg_form}"'])
    rng = np.random.default_rng(1)
    sim.state.v[:] = 0.5 * rng.standard_normal(sim.state.v.shape)
    sim.state.u[:] = 0.005 * rng.standard_normal(sim.state.u.shape)
    sim.compute_forces()
    m = sim.quantity("mass")[:, None]
    p0 = (m * sim.quantity("velocity")).sum(axis=0)
    force = sim.quantity("force")
    scale = np.abs(force).sum()
    assert np.abs(force.sum(axis=0)).max() < 1e-13 * scale
    for _ in range(200):
        sim.step()
    m, v = sim.quantity("mass")[:, None], sim.quantity("velocity")
    p1 = (m * v).sum(axis=0)
    assert np.abs(p1 - p0).max() < 1e-12 * (m * np.abs(v)).sum()


def test_force_forms_agree():
    forces = []
    for form in ("pair", "virtual_work"):
        sim = simulation(random_set_2d(hourglass=50.0, model="neo_hookean"),
                         [f'formulation.force_form="{form}"'])
        sim.state.u[:] = 0.005 * np.random.default_rng(2).standard_normal(sim.state.u.shape)
        sim.compute_forces()
        forces.append(sim.quantity("force"))
    assert np.abs(forces[0] - forces[1]).max() < 1e-12 * np.abs(forces[0]).max()


@pytest.mark.parametrize("hg_form", ["paper", "variational"])
def test_spinning_body_keeps_its_angular_momentum(hg_form):
    sim = simulation(block_2d(model="neo_hookean", hourglass=50.0, form=hg_form) + """
[[initial]]
type = "angular_velocity"
omega = [20.0]
center = [0.5, 0.3]
""")
    rows = run_until(sim, 0.2, every=50)
    L = rows["angular_momentum"]
    assert abs(L[0]) > 1.0
    assert np.abs(L - L[0]).max() < 1e-10 * abs(L[0])
    # it really spun: by 0.2 s the body turned 4 rad
    F = sim.quantity("deformation_gradient")
    assert np.abs(np.arctan2(F[:, 1, 0], F[:, 0, 0])).max() > 0.5


def test_variational_hourglass_conserves_energy():
    sim = simulation(random_set_2d(hourglass=50.0, model="neo_hookean") + """
[[initial]]
type = "displacement_gradient"
gradient = [[0.05, 0.02], [0.0, -0.05]]
center = [0.5, 0.5]
""", ["time.cfl=0.3"])  # the explicit step's energy oscillation grows as dt^2: bounded at cfl 0.3
    rows = run_until(sim, 0.2, every=20)
    e = rows["total_energy"]
    assert rows["hourglass_energy"].max() > 1e-3 * e[0]  # the penalty is active
    assert np.abs(e - e[0]).max() < 2e-3 * e[0]


def test_singular_correction_matrix_names_the_particle():
    from parsph.errors import InputError

    # a 1-particle-wide row: every L is singular in y (all neighbours collinear)
    text = block_2d().replace("upper = [1.0, 0.6]", "upper = [1.0, 0.1]")
    with pytest.raises(InputError, match=r"correction matrix L of particle \d+ at \(.*\) is singular"):
        simulation(text)


def test_body_force_accelerates_a_free_body_uniformly_and_does_work():
    sim = simulation(block_2d(hourglass=50.0) + """
[loads]
body_acceleration = [0.0, -9.81]
""")
    rows = run_until(sim, 0.05)
    assert np.abs(sim.state.acc - [0.0, -9.81]).max() < 1e-9
    t = sim.t
    assert np.abs(sim.quantity("displacement")[:, 1] + 0.5 * 9.81 * t * t).max() < 1e-9
    e = rows["total_energy"]
    assert rows["external_work"][-1] == pytest.approx(rows["kinetic_energy"][-1], rel=1e-9)
    assert np.abs(e - e[0]).max() < 1e-9 * rows["kinetic_energy"][-1]


def test_debug_id_check_notices_a_lost_or_duplicated_particle():
    from parsph.diagnostics import check_particle_ids
    from parsph.errors import ParsphError

    sim = simulation(block_2d())
    check_particle_ids(sim)
    sim.state.gid[0] = sim.state.gid[1]
    with pytest.raises(ParsphError, match="lost or duplicated"):
        check_particle_ids(sim)


def test_flattened_particle_stops_the_run_with_a_clear_message():
    from parsph.errors import ParsphError

    sim = simulation(block_2d(model="neo_hookean"))
    sim.state.F[:] = np.eye(2)
    sim.state.F[3] = np.diag([1.0, 0.0])  # squashed flat in y: no stable step exists
    with pytest.raises(ParsphError, match="time step collapsed"):
        sim.stable.limit(sim.state, sim.topology, sim.interactions, sim.step_count, sim.t)


@pytest.mark.parametrize("dim", [1, 2, 3])
def test_principal_stretches_match_the_singular_values_of_F(dim):
    from parsph.formulations.tlsph import principal_stretches

    rng = np.random.default_rng(dim)
    scratch = np.empty((3, 3))
    for _ in range(100):
        F = np.eye(dim) + 0.8 * rng.standard_normal((dim, dim))
        sv = np.linalg.svd(F, compute_uv=False)
        smallest, largest = principal_stretches(F, dim, scratch)
        assert smallest == pytest.approx(sv.min(), abs=1e-7 * sv.max())
        assert largest == pytest.approx(sv.max(), rel=1e-7)
    assert principal_stretches(np.eye(dim), dim, scratch) == pytest.approx((1.0, 1.0))


def test_energy_balance_holds_while_a_prescribed_motion_accelerates_particles():
    """During the ramp of beam_bending's tip displacement the constraint does work that changes
    the kinetic energy of the prescribed particles; the external work counts it, so
    kinetic + strain + hourglass - external stays constant throughout (without it the
    balance was off by the tip particles' kinetic energy, 1.4 % of the work)."""
    sim = simulation("beam_bending", ["parameters.n=4", "time.damping=0", "time.end=6e-5", "time.cfl=0.3"])
    assert sim.scene.bc[1].type == "displacement" and sim.scene.bc[1].ramp == 5e-5
    r = run_until(sim, 6e-5)
    work = np.abs(r["external_work"]).max()
    assert work > 0
    assert np.abs(r["total_energy"] - r["total_energy"][0]).max() < 1e-6 * work


def _stage_call(sim, kernel: str):
    """A stage's call (compiled kernel and arguments) in the body's next step."""
    with Recorder(sim) as recorder:
        sim.step()
    return next(call for call in recorder.calls if call.kernel.py_func.__name__ == kernel)


# per case, the kernels' outputs the test holds to their sources (the rows' values written)
STAGE_OUTPUTS = {"forces": ("f_int", "f_hg", "omega_hg2"), "kinematics_stress": ("fs", "VP", "S", "psi", "hg_psi")}


@pytest.mark.parametrize("kernel", ["forces", "kinematics_stress"])
@pytest.mark.parametrize("case", ["cube paper", "random 2D variational", "taylor viscous"])
def test_the_compiled_stages_give_the_bits_of_their_python_sources(case, kernel):
    """The stages form their hourglass terms lane by lane, in SIMD instructions
    (parsph.pair_lanes), and sum them in row order afterwards; the compiler may not fuse,
    reorder or drop an operation. Their Python sources, one IEEE operation at a time, give
    the same bits, on rows that take every branch: the stable step's bounds formed, and with
    the viscous rule pairs that have yielded. (Fused multiply-adds fail this test.)"""
    if case == "cube paper":
        sim = simulation(cube("neo_hookean"), ['formulation.hourglass_form="paper"'])
    elif case == "random 2D variational":
        sim = simulation(random_set_2d(hourglass=50.0), ['formulation.force_form="virtual_work"'])
    else:
        sim = simulation("taylor_impact", ['formulation.plastic_hourglass="viscous"'])
    if case != "taylor viscous":
        rng = np.random.default_rng(4)
        sim.state.u[:] = 0.01 * rng.standard_normal(sim.state.u.shape)
        sim.state.v[:] = 0.5 * rng.standard_normal(sim.state.v.shape)
        sim.compute_forces()
    for _ in range(60 if case == "taylor viscous" else 1):  # (every kernel of a step compiled)
        sim.step()
    call = _stage_call(sim, kernel)
    names = list(inspect.signature(call.kernel.py_func).parameters)
    args = list(call.args)
    if case == "taylor viscous":
        yielded = np.flatnonzero(sim.quantity("plastic_strain") > 1e-3)
        assert len(yielded) > 20
        args[0], args[1] = int(yielded[0]), int(yielded[0]) + 40
    else:
        args[0], args[1] = 0, min(60, sim.state.n_owned)
    rows = slice(args[0], args[1])
    outputs = list(STAGE_OUTPUTS[kernel])
    if kernel == "forces":
        args[names.index("bound")] = True
        outputs += ["damper_rate2"] if case == "taylor viscous" else []
    elif case != "random 2D variational":
        outputs.remove("hg_psi")  # the variational form's penalty only
    for name in outputs:
        args[names.index(name)] = np.full_like(args[names.index(name)], np.nan)
    compiled = [a.copy() if isinstance(a, np.ndarray) else a for a in args]
    source = [a.copy() if isinstance(a, np.ndarray) else a for a in args]
    call.kernel(*compiled)
    with python_sources():
        call.kernel.py_func(*source)
    for name in outputs:
        k = names.index(name)
        assert np.all(np.isfinite(compiled[k][rows])), name
        # (the yielded rows' springs are off, and so their bound)
        assert np.any(compiled[k][rows] != 0.0) or (name, case) == ("omega_hg2", "taylor viscous"), name
        if name in ("omega_hg2", "damper_rate2"):  # from the bound's tensor by acos and cos, whose
            # last bit differs between the compiled code's math library and Python's
            assert np.allclose(compiled[k], source[k], rtol=1e-13, atol=0.0, equal_nan=True), name
        else:
            assert np.array_equal(compiled[k], source[k], equal_nan=True), name
    if kernel == "forces":
        tensor = names.index("tensor")  # the last row's bound tensor (the damper's, with the viscous rule)
        assert np.any(compiled[tensor] != 0.0) and np.array_equal(compiled[tensor], source[tensor])
