"""Johnson-Cook failure (parsph/materials/johnson_cook_failure.py): the damage index of a
material point along paths of constant triaxiality against the closed form, the point's
failure, the keys' rules, and a bar that breaks where its plastic strain reached the strain
to fracture."""

from __future__ import annotations

import math

import numpy as np
import pytest

from parsph.errors import InputError
from parsph.formulations.tlsph import REFERENCE_INITIAL, stress_at
from parsph.materials import constants, damage, elastoplastic
from parsph.materials import johnson_cook_failure as jcf
from parsph.materials.elastoplastic import PLASTIC_STRAIN, initial_state
from parsph.materials.update import J2_PLASTICITY, JOHNSON_COOK, WORK
from physics import run_until, scene_from, simulation

STEEL = dict(model="j2_plasticity", density=7850.0, youngs_modulus=200e9, poisson_ratio=0.3, yield_stress=400e6,
             hardening_modulus=0.0, jc_d1=0.05, jc_d2=0.5, jc_d3=-1.5, jc_d4=0.0, jc_d5=0.0)
COPPER = dict(model="johnson_cook", density=8960.0, youngs_modulus=124e9, poisson_ratio=0.34, jc_a=90e6,
              jc_b=292e6, jc_n=0.31, jc_c=0.025, jc_m=1.09, reference_strain_rate=1.0, room_temperature=294.0,
              melting_temperature=1356.0, specific_heat=383.0, taylor_quinney=0.9,
              jc_d1=0.54, jc_d2=4.89, jc_d3=-3.03, jc_d4=0.014, jc_d5=1.12)  # Johnson & Cook 1985, OFHC copper


class Point:
    """One material point of `material` with Johnson-Cook failure, evaluated by the
    formulations' compiled stress update (formulations.tlsph.stress_at) and committed."""

    def __init__(self, material: dict):
        self.law = {"j2_plasticity": J2_PLASTICITY, "johnson_cook": JOHNSON_COOK}[material["model"]]
        self.c = constants(dict(material, failure_strain=None)).values
        self.state, self.trial = initial_state(1), initial_state(1)
        self.damaged, self.damaged_trial = damage.initial_state(1), damage.initial_state(1)
        self.F, self.VP, self.J, self.psi = np.zeros((1, 3, 3)), np.zeros((1, 3, 3)), np.ones(1), np.zeros(1)
        self.P, self.work = np.zeros((3, 3)), np.zeros((WORK, 3, 3))

    def evaluate(self, F: np.ndarray, dt: float) -> np.ndarray:
        """The Kirchhoff stress at F from the committed state (the trial rows written)."""
        self.F[0] = F
        stress_at(3, self.law, REFERENCE_INITIAL, jcf.JOHNSON_COOK_FAILURE, 0, self.F, self.F, 1.0, self.c,
                  self.state, self.trial, self.damaged, self.damaged_trial, self.P, self.work, self.F, self.VP,
                  self.J, self.psi, dt)
        return self.P @ F.T

    def commit(self) -> None:
        self.state[:] = self.trial
        self.damaged[:] = self.damaged_trial
        jcf.fail(self.damaged)

    @property
    def index(self) -> float:
        return float(self.damaged[0, jcf.INDEX])


def fracture_strain(m: dict, triaxiality: float, rate: float = 1.0, temperature: float = 0.0) -> float:
    return (m["jc_d1"] + m["jc_d2"] * math.exp(m["jc_d3"] * triaxiality)) * \
        (1.0 + m["jc_d4"] * math.log(max(rate, 1.0))) * (1.0 + m["jc_d5"] * temperature)


def test_isochoric_stretch_fails_at_the_strain_to_fracture_of_zero_triaxiality():
    """F = diag(e^s, e^(-s/2), e^(-s/2)) keeps J = 1 and the Kirchhoff stress deviatoric:
    triaxiality 0, so D = eps_bar / (D1 + D2) along the whole path (to round-off); the point
    fails at the first commit where D >= 1, and from then carries no stress."""
    point = Point(STEEL)
    limit = fracture_strain(STEEL, 0.0)
    failed_at = None
    for k in range(1, 1001):
        s = 1e-3 * k
        point.evaluate(np.diag([math.exp(s), math.exp(-0.5 * s), math.exp(-0.5 * s)]), 1e-6)
        plastic = point.trial[0, PLASTIC_STRAIN]
        assert point.damaged_trial[0, jcf.INDEX] == pytest.approx(plastic / limit, rel=1e-10)
        point.commit()
        if point.damaged[0, damage.DAMAGE] >= 1.0:
            failed_at = plastic
            break
    assert failed_at is not None and limit <= failed_at < limit + 2e-3  # one step of 1e-3 in s
    tau = point.evaluate(np.diag([1.6, 0.8, 0.8]), 1e-6)
    assert not tau.any() and point.psi[0] == 0.0


def uniaxial(point: Point, strain: float, steps: int, dt: float) -> list:
    """Uniaxial stress along x to the log strain `strain`: at each step the lateral stretch
    that leaves tau_yy = tau_zz = 0 (secant iteration), then the commit. Returns the plastic
    strain increments and the Kirchhoff stress of each step."""
    lateral, out = 1.0, []
    for k in range(1, steps + 1):
        axial = math.exp(strain * k / steps)

        def residual(t):
            return point.evaluate(np.diag([axial, t, t]), dt)[1, 1]

        a, b = lateral, lateral * (1.0 - 1e-4)
        ra, rb = residual(a), residual(b)
        for _ in range(60):
            if abs(rb) <= 1e-12 * STEEL["yield_stress"] or rb == ra:
                break
            a, b, ra = b, b - rb * (b - a) / (rb - ra), rb
            rb = residual(b)
        lateral = b
        tau = point.evaluate(np.diag([axial, lateral, lateral]), dt)
        out.append((point.trial[0, PLASTIC_STRAIN] - point.state[0, PLASTIC_STRAIN], tau))
        point.commit()
    return out


def test_uniaxial_tension_accumulates_at_triaxiality_one_third_with_the_rate_term():
    """Uniaxial stress has triaxiality 1/3 exactly; with D4 the strain to fracture grows with
    ln of the plastic strain rate d_eps / dt of each step (eps_dot_0 = 1/s for J2): the index
    is the sum of d_eps / eps_f(1/3, rate) to 1e-8, and the stresses' triaxiality is 1/3."""
    material = dict(STEEL, jc_d4=0.05)
    point = Point(material)
    dt = 1e-5
    steps = uniaxial(point, 0.05, 200, dt)
    expected = sum(step / fracture_strain(material, 1.0 / 3.0, step / dt) for step, _ in steps if step > 0.0)
    assert expected > 0.05
    assert point.index == pytest.approx(expected, rel=1e-8)
    tau = steps[-1][1]
    dev = tau - np.trace(tau) / 3.0 * np.eye(3)
    assert np.trace(tau) / 3.0 / math.sqrt(1.5 * np.sum(dev * dev)) == pytest.approx(1.0 / 3.0, rel=1e-9)


def test_johnson_cook_copper_heats_towards_its_strain_to_fracture():
    """With the Johnson-Cook law the homologous temperature of the plastic work's heat
    enters through D5: along the isochoric stretch (triaxiality 0) the index is the sum of
    d_eps / eps_f(0, rate, T*) with T* of each step's plastic work."""
    point = Point(COPPER)
    c = point.c
    rate0, heating = c[-4], c[-3]
    assert heating == pytest.approx(COPPER["taylor_quinney"] / (
        COPPER["density"] * COPPER["specific_heat"] * (COPPER["melting_temperature"] - COPPER["room_temperature"])))
    assert rate0 == COPPER["reference_strain_rate"]
    dt, expected = 1e-6, 0.0
    for k in range(1, 801):
        s = 1e-3 * k
        point.evaluate(np.diag([math.exp(s), math.exp(-0.5 * s), math.exp(-0.5 * s)]), dt)
        step = point.trial[0, PLASTIC_STRAIN] - point.state[0, PLASTIC_STRAIN]
        if step > 0.0:
            temperature = heating * point.trial[0, elastoplastic.PLASTIC_WORK]
            expected += step / fracture_strain(COPPER, 0.0, step / dt / rate0, temperature)
        point.commit()
    assert point.index == pytest.approx(expected, rel=1e-9)
    assert 0.1 < point.index < 1.0  # copper's eps_f at triaxiality 0 and 1e3/s: about 5.5 to 6.5


@pytest.mark.parametrize("change, message", [
    ({"jc_d1": None}, "material.jc_d2 needs material.jc_d1"),
    ({"failure_strain": 0.1}, "give one failure model"),
    ({"model": "neo_hookean", "yield_stress": None, "hardening_modulus": None},
     "Johnson-Cook failure accumulates plastic strain and applies to the plastic laws"),
])
def test_johnson_cook_failure_keys_are_checked(change, message):
    text = ("[scene]\nname = 'jcf'\ndimension = 2\n[[geometry.parts]]\nshape = 'box'\nlower = [0.0, 0.0]\n"
            "upper = [1e-3, 1e-3]\nspacing = 2.5e-4\n[time]\nend = 1e-6\n[material]\n")
    for key, value in dict(STEEL, **change).items():
        if value is not None:
            text += f"{key} = {value!r}\n".replace("'", '"')
    with pytest.raises(InputError, match=message.replace(".", r"\.")):
        scene_from(text)


BAR = """
[scene]
name = "jc_bar"
dimension = 2
[[geometry.parts]]
shape = "box"
lower = [-6e-3, -1e-3]
upper = [6e-3, 1e-3]
spacing = 5e-4
[kernel]
support = 2.0
[material]
model = "j2_plasticity"
density = 7850.0
youngs_modulus = 200e9
poisson_ratio = 0.3
yield_stress = 400e6
hardening_modulus = 0.0
jc_d1 = 0.05
jc_d2 = 0.5
jc_d3 = -1.5
break_pairs = true
[formulation]
hourglass = 50.0
hourglass_form = "paper"
[time]
end = 1.0e-4
[groups.left]
box = { lower = [-1.0, -1.0], upper = [-5e-3, 1.0] }
[groups.right]
box = { lower = [5e-3, -1.0], upper = [1.0, 1.0] }
[[bc]]
type = "velocity"
group = "left"
value = [-20.0, 0.0]
ramp = 1e-5
[[bc]]
type = "velocity"
group = "right"
value = [20.0, 0.0]
ramp = 1e-5
"""


def test_a_pulled_bar_breaks_where_its_plastic_strain_reached_the_strain_to_fracture():
    """A plane-strain J2 bar pulled apart at 40 m/s fails (D = 1) only at particles whose
    committed index reached 1, after plastic strain of the order of eps_f; with
    break_pairs the halves part and the pull's force falls; the balance, with the work the
    failed particles took as damage work, closes."""
    sim = simulation(BAR)
    peak = {"force": 0.0}

    def pull(s):
        force = float(s.quantity("reaction")[s.group_index("right"), 0].sum())
        peak["force"] = max(peak["force"], force)
        return force

    h = run_until(sim, 1.0e-4, every=20, probe=pull)
    state = sim.state.damage_state(sim.state.bodies[0])[0][: sim.state.n_owned]
    failed = state[:, damage.DAMAGE] >= 1.0
    assert failed.any()
    assert np.all(state[failed, jcf.INDEX] >= 1.0) and np.all(state[~failed, jcf.INDEX] < 1.0)
    # the plastic strain where it broke: eps_f between uniaxial stress's triaxiality, 1/3, and
    # 0.8, about plane-strain tension's 1/sqrt(3) (eps_f 0.260; measured 0.262)
    plastic = sim.quantity("plastic_strain")[failed].max()
    assert fracture_strain(STEEL, 0.8) < plastic < fracture_strain(STEEL, 1.0 / 3.0)
    assert h["damage_work"][-1] > 0.0
    # parted: the grip rings the free half about zero force (measured mean 0.25 % of the peak)
    late = h["time"] > 0.6e-4
    assert abs(h["probe"][late].mean()) < 0.1 * peak["force"]
    # balance (measured 9e-5 of the work done)
    assert np.abs(h["total_energy"] - h["total_energy"][0]).max() < 1e-3 * h["external_work"].max()


def test_damage_work_is_zero_until_a_particle_fails():
    """The pulled bar up to 2.5e-5 s, before its first particle fails (3.0e-5 s): yielding
    particles near failure (index above 0.5) have taken no damage work, and every energy of
    the history is the same, bit for bit, as without the failure model (the law's stress is
    untouched, and the trapezoidal rule's difference from the law's own energies is not
    damage work)."""
    with_failure = run_until(simulation(BAR), 2.5e-5, every=10, probe=lambda s: s.quantity("failure_index").max())
    plain = BAR.replace("jc_d1 = 0.05\njc_d2 = 0.5\njc_d3 = -1.5\nbreak_pairs = true\n", "")
    without = run_until(simulation(plain), 2.5e-5, every=10)
    assert 0.5 < with_failure["probe"][-1] < 1.0 and with_failure["plastic_work"][-1] > 0.0
    assert np.all(with_failure["damage_work"] == 0.0)
    for name in ("kinetic_energy", "strain_energy", "plastic_work", "total_energy"):
        assert np.array_equal(with_failure[name], without[name]), name


def test_the_copper_rod_with_johnson_and_cooks_failure_constants_takes_no_damage_work():
    """runs/taylor_jc at 8 layers with copper's failure constants (COPPER) to 5 us: the foot
    yields and its index grows, no particle fails, and the damage work is 0 in every row
    (it read -0.41 J, the trapezoidal rule's difference from the law's plastic work)."""
    constants = [f"material.{k}={COPPER[k]}" for k in ("jc_d1", "jc_d2", "jc_d3", "jc_d4", "jc_d5")]
    h = run_until(simulation("taylor_jc", ["parameters.layers=8", *constants]), 5e-6, every=10,
                  probe=lambda s: s.quantity("failure_index").max())
    assert h["plastic_work"][-1] > 0.0 and 0.1 < h["probe"][-1] < 1.0
    assert np.all(h["damage_work"] == 0.0)
