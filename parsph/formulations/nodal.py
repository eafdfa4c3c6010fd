"""Particle methods with a Lagrangian kernel and nodal integration, behind one interface:

  tlsph  corrected SPH, total-Lagrangian [G §2]: F_i = I + sum_j (u_j - u_i) (x) g_ij with
         the corrected gradient g_ij = V_j L_i^-1 w_ij, pair-form [G eq. 24] or
         virtual-work [V eq. 11] forces, hourglass control [G eq. 25-32] (a yielded
         elasto-plastic particle's modulus in it is its yield stress [G §4.5])
  ulsph  the same from an updated reference X^r [V §3.1], optionally stabilised by
         Hessian's difference [V eq. 17, 21]
  sph    symmetrised SPH [R eq. 21-25, 57, Table 1]: the plain kernel gradient
         g_ij = V_j grad_i W_ij, forces f_i = V_i sum_j (P_i + P_j) g_ij (momentum-conserving)
  rlm    Randles-Libersky normalisation [R eq. 33-34, Table 1]: the corrected gradient in
         F and in the force row f_i = V_i sum_j (P_i + P_j) g_ij (the sign printed in
         [R] corrected; not momentum-conserving)

sph and rlm take an Eulerian kernel (`kernel = "eulerian"`, [R eq. 16, Table 2]) as the
updated reference rebuilt at every step: kernel, neighbours and corrections in the current
configuration, F = f F^r, the forces with the stress carried to the current configuration
(V^r P F^rT = V sigma), the state carried through the rebuilds like the updated reference's.

All four evaluate F and the stress at the particles (formulations.tlsph holds the compiled
kernels); `stages` lists the passes of one force evaluation with what each reads and writes.
"""

from __future__ import annotations

import numpy as np

from parsph import stability
from parsph.errors import InputError
from parsph.fields import Field, register
from parsph.formulations import tlsph
from parsph.formulations.base import Formulation, Running, Stage, bound, check_shared_keys
from parsph.formulations.reference import PairOptions
from parsph.kernels.functions import KERNEL_NAMES
from parsph.keys import Key, non_negative, one_of
from parsph.materials import damage, update

# the updated reference [V §3.1], carried when a body updates its reference (ulsph, or an
# Eulerian kernel)
UPDATED_FIELDS = (
    Field("Xr", "point", owner="updated", doc="reference position X^r of the updated reference [m]"),
    Field("Fr", "tensor", owner="updated", doc="deformation gradient of the updated reference"),
    Field("measure_r", "scalar", owner="updated", doc="measure in the updated reference"),
    Field("volume_r", "scalar", owner="updated", doc="volume in the updated reference [m^3]"),
)
register(*UPDATED_FIELDS)
EULERIAN = ("{path}.kernel = 'eulerian' is available for type = 'sph', 'rlm', 'kbm' and 'efg' with nodal "
            "integration (for corrected SPH use type = 'ulsph' with update_every = 1)")


class NodalFormulation(Formulation):
    """One body's formulation: its options and compiled stages (the members: base.Formulation)."""

    TYPES = {  # formulation.type names it serves
        "tlsph": "corrected SPH, total-Lagrangian [G]",
        "ulsph": "the same from an updated reference [V §3.1]",
        "sph": "symmetrised SPH",
        "rlm": "Randles-Libersky normalisation [R Table 1] (Lagrangian kernel, nodal integration)",
    }
    KEYS = {  # its formulation keys (the other families refuse those that do not apply to them)
        "hessian": Key("float", 0.0, non_negative, "Hessian's-difference stabilisation eta [V eq. 17]"),
        "hessian_correction": Key("str", "weighted", one_of("weighted", "paper"),
                                  "linear correction of the kernel Hessian: weighted: the A term "
                                  "weighted by the kernel (continuous as neighbours enter the "
                                  "support); paper: unweighted [V eq. 19]"),
        "update_every": Key("int", 0, non_negative, "ulsph: update the reference every N steps (0 = off)"),
        "update_strain": Key("float", 0.0, non_negative,
                             "ulsph: update when the largest principal log strain since the reference "
                             "exceeds this (0 = off)"),
        "force_form": Key("str", "pair", one_of("pair", "virtual_work"),
                          "tlsph, ulsph: the forces in the pair form [G eq. 24] or the virtual-work form "
                          "[V eq. 11]"),
        "hourglass": Key("float", None, non_negative,
                         "hourglass coefficient alpha [G eq. 31]; default 50 for tlsph and ulsph, "
                         "0 for sph, rlm and kbm (the methods as [R] compares them)"),
        "hourglass_form": Key("str", "variational", one_of("paper", "variational"),
                              "paper: [G eq. 32]; variational: forces from the penalty energy"),
        "viscosity": Key("float", 0.0, non_negative,
                         "Monaghan's artificial viscosity alpha (0: none; for fluids; particle formulations)"),
        "viscosity_beta": Key("float", 0.0, non_negative, "Monaghan's artificial viscosity beta"),
        "plastic_hourglass": Key("str", "yield_stress", one_of("yield_stress", "elastic", "viscous"),
                                 "j2_plasticity, the hourglass force of a yielded particle: its yield stress "
                                 "as modulus [G §4.5] (yield_stress), E throughout (elastic), or LAMMPS "
                                 "MACHDYN's viscous force for a pair with a plastic strain above 1e-3 "
                                 "(viscous; hourglass_form = 'paper')"),
    }
    damage = True  # tensile damage (materials.damage) at its particles

    @staticmethod
    def resolve(path: str, form: dict) -> None:
        """Its defaults and rules on a formulation table `form` checked against the schema
        (InputError naming the key at `path`)."""
        kind = form["type"]
        if form["hourglass"] is None:
            form["hourglass"] = 50.0 if kind in ("tlsph", "ulsph") else 0.0
        if kind == "ulsph" and not (form["update_every"] or form["update_strain"]):
            raise InputError(f"{path}.type = 'ulsph' needs an update trigger: {path}.update_every "
                             f"(steps) or {path}.update_strain (log strain)")
        if form["kernel"] == "eulerian" and kind not in ("sph", "rlm"):
            raise InputError(EULERIAN.format(path=path))
        if form["integration"] is not None:
            raise InputError(f"{path}.integration applies to type = 'efg'")
        del form["integration"]  # absent, as in scenes written before the key existed (checkpoints compare scenes)
        check_shared_keys(path, form, kind, NodalFormulation.moves_reference(form))

    @staticmethod
    def moves_reference(form: dict) -> bool:
        """Whether a formulation table moves its reference (ulsph, the Eulerian kernel)."""
        return form.get("kernel") == "eulerian" or form["type"] == "ulsph"

    def __init__(self, options: dict, dim: int, law: int, failure: int = 0):
        super().__init__(options, dim, law, failure)
        self.eulerian = options.get("kernel") == "eulerian"
        self.updated = self.type == "ulsph" or self.eulerian
        self.conserves_momentum = self.type != "rlm"  # RLM's force row [R Table 1] does not
        self.conserves_energy = self.type != "rlm"  # nor is it the energy's gradient
        self.alpha = options["hourglass"]
        self.hourglass_form = tlsph.HOURGLASS_FORMS[options["hourglass_form"]] if self.alpha > 0 else 0
        self.hourglass_penalty = self.hourglass_form == tlsph.HOURGLASS_VARIATIONAL
        self.absorbs_hourglass_work = self.hourglass_form == tlsph.HOURGLASS_PAPER
        self.plastic_hourglass = options["plastic_hourglass"]  # a yielded particle's: [G §4.5], E or MACHDYN's
        self.viscosity = (options["viscosity"], options["viscosity_beta"])  # Monaghan's alpha, beta
        self.viscous = any(self.viscosity)
        self.eta = options["hessian"]
        self.weighted_hessian = options["hessian_correction"] == "weighted"
        self.update_every, self.update_strain = (1, 0.0) if self.eulerian else \
            (options["update_every"], options["update_strain"])
        force = "rlm" if self.type == "rlm" else options["force_form"]
        self.corrected_stress = force != "rlm"  # its force row reads S = V P L^-1 / V (formulations.tlsph)
        reference = tlsph.REFERENCE_CURRENT if self.eulerian else \
            tlsph.REFERENCE_UPDATED if self.updated else tlsph.REFERENCE_INITIAL
        viscous = self.absorbs_hourglass_work and self.plastic_hourglass == "viscous"
        self.damped = viscous
        self.stage_one_corrects = tlsph.stage_one_corrects(tlsph.FORCE_FORMS[force], self.eta > 0, reference)
        self.gradient, self.kinematics_stress, self.hessian_transpose, self.forces = tlsph.compile_stages(
            dim, law, tlsph.FORCE_FORMS[force], self.hourglass_form, reference, self.eta > 0, failure, viscous)

    @property
    def pair_options(self) -> PairOptions:
        """Corrected gradients (but sph's), its hourglass control and Hessian stabilisation."""
        return PairOptions(corrected=self.type != "sph", hourglass_form=self.hourglass_form, alpha=self.alpha,
                           stabilised=self.eta > 0)

    def quadrature(self, state, body) -> list:
        """[(X, F, w)] of the body's owned integration points: its particles, their volumes."""
        lo, hi = body.lo, body.hi
        return [(state.X[lo:hi], state.F[lo:hi], state.volume[lo:hi])]

    def integrated(self, state, body, density) -> np.ndarray:
        """V^0 q over the body's owned particles, q = density(arrays) per row of the
        particles' arrays (a density per unit reference volume: psi, plastic work)."""
        return state.volume[body.lo:body.hi] * density(state.particles.arrays)[body.lo:body.hi]

    def stages(self, state, body, running: Running) -> list:
        """The passes of one force evaluation over `body`'s owned particles of `state`."""
        hessian, hourglass = self.eta > 0, self.hourglass_form > 0
        dim = state.dim  # the kernels' scratch (they run without Numba's reference counting)
        scratch = (np.empty((dim, dim)), np.empty((update.WORK, 3, 3)))
        tensor = np.empty((3, 3))  # the row's spring tensor, for its largest eigenvalue
        out = []
        motion = "fs" if self.updated else "F"  # the motion from the reference: F itself in the initial one
        if state.updated:  # d apart from u: the displacement since each body's reference
            def displacement():
                lo, hi = body.lo, body.hi
                np.subtract(state.u[lo:hi], state.shift[lo:hi], out=state.d[lo:hi])
            out.append(Stage("kinematics+stress", displacement, writes=("d",)))
        plastic = self.plastic_hourglass == "yield_stress" and body.law.plastic is not None
        viscous = self.plastic_hourglass == "viscous" and hourglass and body.law.plastic is not None
        if hourglass and (plastic or body.failure):
            def hourglass_modulus():  # from the committed state: [G §4.5], and (1 - D) E
                lo, hi = body.lo, body.hi
                modulus = np.full(hi - lo, body.constants.youngs)
                if plastic:  # a yielded point's yield stress in place of E
                    committed = state.material_state(body)[0][lo:hi]
                    modulus = np.where(committed[:, body.law.plastic.strain] > 0.0,
                                       body.law.plastic.yield_stress(body.constants.values, committed), modulus)
                if body.failure:
                    modulus *= damage.hourglass_factor(state.damage_state(body)[0][lo:hi])
                if self.hourglass_form == tlsph.HOURGLASS_VARIATIONAL:
                    # the penalty E_i sum_j c_ij |e_ij|^2 / 2 of the last evaluation drops with the
                    # modulus without work: counted as released (as at reference updates)
                    old = state.youngs[lo:hi]
                    changed = (modulus != old) & (old > 0.0)  # a penalty at E = 0 is 0
                    if changed.any():
                        ratio = modulus / np.where(changed, old, 1.0)
                        drop = np.where(changed, state.hg_psi[lo:hi] * (1.0 - ratio), 0.0)
                        running.ledger.totals["hourglass_released"][body.index].add(drop)
                state.youngs[lo:hi] = modulus
            out.append(Stage("kinematics+stress", hourglass_modulus, writes=("youngs",)))
        if hessian:
            def gradient():
                ref = body.relation.ref
                self.gradient(body.lo, body.hi, ref.ptr, ref.idx, ref.gw, ref.Linv, state.d, state.f)
            out.append(Stage("kinematics+stress", gradient, reads=("d",), writes=("f",)))

        # the parameters the kernels read at neighbours as their compile-time switches decide,
        # bound by name to the fields they take: the stages declare those as read
        fields = dict(d="d", f="f", fs=motion, Fr="Fr" if self.updated else "F")
        neighbours = ("d", "f") if hessian else ("d",)

        def kinematics_stress():
            ref, a = body.relation.ref, bound(state, fields)
            bad = self.kinematics_stress(
                body.lo, body.hi, ref.ptr, ref.idx, ref.gw, ref.Linv, state.reference_measure, ref.q, ref.gh,
                state.reference_positions, ref.hgc, a["d"], state.volume, state.youngs, body.constants.values,
                *state.material_state(body), *state.damage_state(body), a["f"], a["fs"], state.F, a["Fr"], state.VP,
                state.S, state.J, state.psi, state.hg_psi, *scratch, running.dt)
            if bad >= 0:
                raise stability.unstable_particle(running, state, bad)
        states = tuple(name for name in (body.law.state, "damage" if body.failure else None)
                       if name)
        trials = tuple(name + "_trial" for name in states)  # the new states it computes
        out.append(Stage("kinematics+stress", kinematics_stress, reads=tuple(fields[p] for p in neighbours),
                         writes=("fs", "F", "VP", "J", "psi", "hg_psi") + (("S",) if self.stage_one_corrects else ())
                         + trials))
        if hessian:
            def hessian_transpose():
                ref = body.relation.ref
                self.hessian_transpose(body.lo, body.hi, ref.ptr, ref.idx, ref.gh, ref.gh_rev, state.VP, state.B,
                                       ref.Linv, state.reference_measure, state.S)
            out.append(Stage("forces", hessian_transpose, reads=("VP",), writes=("B", "S"), force_row=True))
        elif self.corrected_stress and self.eulerian:  # S in the reference the forces use, once it has moved
            def corrected_stresses():
                tlsph.corrected_stresses(body.lo, body.hi, state.VP, body.relation.ref.Linv, state.reference_measure,
                                         state.S)
            out.append(Stage("forces", corrected_stresses, writes=("S",), force_row=True))

        # MACHDYN's viscous hourglass force: alpha, the wave speed, density, E, the plastic strain's column
        constants = np.array([self.alpha, body.constants.wave_speed, body.density, body.constants.youngs,
                              body.law.plastic.strain if viscous else 0], float)
        kind = KERNEL_NAMES.index(body.relation.kernel)

        force_fields = dict(d="d", fs=motion, VP="VP", S="S", youngs="youngs", v="v",
                            plastic=body.law.state + "_trial" if viscous else "no_state")
        # the stress at the neighbours: S (pair and virtual-work rows), V P (RLM's row, the q terms)
        stress = (("S",) if self.corrected_stress else ()) + (("VP",) if hessian or not self.corrected_stress else ())
        force_neighbours = stress + (("d", "fs", "youngs") if hourglass else ()) + (("v", "plastic") if viscous else ())

        def forces():
            ref, a = body.relation.ref, bound(state, force_fields)
            self.forces(body.lo, body.hi, ref.ptr, ref.idx, ref.gw, ref.gw_sum, ref.Linv, state.reference_measure,
                        ref.q, ref.q_rev, ref.q_sum, state.reference_positions, ref.hgc, a["d"], a["fs"], a["VP"],
                        a["S"], a["youngs"], state.volume, state.mass, state.f_int, state.f_hg,
                        running.stable.bound_hourglass, state.omega_hg2, state.damper_rate2, tensor, a["v"],
                        a["plastic"], state.support, kind, constants)
        reads = tuple(force_fields[p] for p in force_neighbours)
        out.append(Stage("forces+hourglass" if hourglass else "forces", forces, reads=reads,
                         writes=("f_int", "f_hg", "omega_hg2", "damper_rate2"), force_row=True))
        if any(self.viscosity):
            def viscosity():
                ref = body.relation.ref
                tlsph.artificial_viscosity(
                    body.lo, body.hi, ref.ptr, ref.idx, ref.gw, ref.Linv, state.reference_measure,
                    state.reference_positions, state.d, state.v,
                    state.J, body.density, state.volume_r if self.updated else state.volume, state.mass,
                    state.support, body.constants.wave_speed, *self.viscosity, state.f_visc, state.viscous_heating,
                    state.step_limit)
            out.append(Stage("viscosity", viscosity, reads=("d", "v", "J"), writes=("f_visc", "viscous_heating", "step_limit"),
                             force_row=True))
        return out

