"""Global diagnostics and probes: exact sums over all particles (exact_sum), the same bit
for bit on any number of ranks.

Disorder: the mass-weighted RMS and the maximum of the hourglass error eta_i
(formulations.tlsph.hourglass_error). Energies: kinetic, strain (sum V psi), plastic work
(dissipated), damage work (taken by damaged and failed particles beyond their strain
energy: materials.damage), viscous work (absorbed by the artificial viscosity), hourglass
(minus the work done by the hourglass forces), contact (the potential of the contact
between bodies: parsph.contact), contact work (absorbed by its damping and friction),
external work (body force, constraint reactions, obstacles' contact and the work that
changes the kinetic energy of prescribed motions) and the balance total = kinetic +
strain + plastic + damage + viscous + hourglass + contact + contact work + damping work -
external, which is constant for an exact integration. Momenta: linear (vector) and angular
(scalar in 2D, vector in 3D), and their defects: the change that the forces between
particles made (parsph.ledger; zero for forces equal, opposite and collinear in pairs). The
radius of gyration of the particles about their centre of mass.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from parsph import readouts
from parsph.exact_sum import SCALE, Exact, totals
from parsph.fields import MOMENT_COMPONENTS
from parsph.interactions import TERMS
from parsph.rigid import moments


@njit(cache=True)
def particle_columns(mass, v, X, u, eta):
    """The per-particle terms of the row's sums, (n, 2 + 2 d + a): m eta^2, m, the kinetic
    energy per component (m v_a^2 / 2), the momentum m v and the angular momentum x cross
    m v (a = 1 component in 2D, 3 in 3D, none in 1D), x = X + u."""
    n, dim = len(eta), v.shape[1]
    turns = 1 if dim == 2 else (3 if dim == 3 else 0)
    out = np.empty((n, 2 + 2 * dim + turns))
    p = np.empty(dim)
    x = np.empty(dim)
    for i in range(n):
        m = mass[i]
        out[i, 0] = m * eta[i] * eta[i]
        out[i, 1] = m
        for a in range(dim):
            p[a] = m * v[i, a]
            x[a] = X[i, a] + u[i, a]
            out[i, 2 + a] = 0.5 * m * v[i, a] * v[i, a]
            out[i, 2 + dim + a] = p[a]
        if dim == 2:
            out[i, 2 + 2 * dim] = x[0] * p[1] - x[1] * p[0]
        elif dim == 3:
            out[i, 2 + 2 * dim] = x[1] * p[2] - x[2] * p[1]
            out[i, 3 + 2 * dim] = x[2] * p[0] - x[0] * p[2]
            out[i, 4 + 2 * dim] = x[0] * p[1] - x[1] * p[0]
    return out


class RowReduction:
    """The parts of a history row that every rank contributes, reduced over the ranks in
    one message: exact sums (exact_sum.Exact) and maxima. Each contributor adds its parts
    and reads its results after `reduce` by the position `add_sums` / `add_max` returned."""

    def __init__(self, comm):
        self.comm = comm
        self.items, self.count, self.maxima = [], 0, []
        self.sums = []

    def add_sums(self, items: list) -> int:
        """Add exact sums (exact_sum.totals' items: Exact, or arrays summed locally at
        `reduce`); returns the position of the first."""
        first = self.count
        self.items.extend(items)
        self.count += sum(np.shape(x)[1] if np.ndim(x) == 2 else 1 for x in items)
        return first

    def add_max(self, values: list) -> int:
        """Add maxima over the ranks (a minimum as the maximum of its negation); returns the
        position of the first."""
        self.maxima.extend(float(v) for v in values)
        return len(self.maxima) - len(values)

    def reduce(self) -> None:
        """Collective: the sums over all ranks (exact, the same on every rank count) and the
        maxima."""
        self.sums = totals(self.items)
        if self.comm.size == 1:
            return
        gathered = self.comm.allgather(([p.units for p in self.sums], [p.special for p in self.sums], self.maxima))
        units, special, maxima = zip(*gathered)
        self.sums = [Exact(sum(u), sum(s)) for u, s in zip(zip(*units), zip(*special))]
        self.maxima = [math.nan if any(math.isnan(v) for v in m) else max(m) for m in zip(*maxima)]


def probe_parts(probes: list, sim, reduction: RowReduction):
    """Each probe's part of the row: the reduction of a particle quantity over its group.
    Returns the function that gives the probes' values once `reduction` is reduced."""
    where = []
    for probe in probes:
        sel = sim.group_index(probe.group)
        q = sim.quantity(probe.quantity, sel)
        if q.ndim == 2:
            q = np.linalg.norm(q, axis=1) if probe.component < 0 else q[:, probe.component]
        how = probe.reduce
        if how in ("mean", "sum"):
            where.append(reduction.add_sums([q, Exact(len(q) * SCALE)]))
        elif how == "max":
            where.append(reduction.add_max([q.max() if len(q) else -np.inf]))
        else:
            where.append(reduction.add_max([-q.min() if len(q) else -np.inf]))

    def values() -> dict:
        out = {}
        for probe, k in zip(probes, where):
            how = probe.reduce
            if how in ("mean", "sum"):
                value, count = float(reduction.sums[k]), float(reduction.sums[k + 1])
                out[probe.name] = value / count if how == "mean" else value
            else:
                out[probe.name] = reduction.maxima[k] if how == "max" else -reduction.maxima[k]
        return out

    return values


def global_parts(sim, reduction: RowReduction):
    """This rank's parts of the energies (the ledger's terms: parsph.ledger), momenta and
    disorder of all bodies together, and with more than one body of each body's energies.
    Returns the function that gives them as "NAME" and "NAME.BODY" once `reduction` is
    reduced."""
    dim = sim.state.dim
    eta = readouts.disorder(sim)
    columns = particle_columns(sim.ledger.masses(sim.state), sim.state.v, sim.state.X, sim.state.u, eta)
    energies = sim.ledger.items(sim)
    bodies = sim.state.bodies
    start = reduction.add_sums([columns])
    n, A = sim.state.n_owned, sim.state.particles.arrays
    x = sim.state.X[:n] + sim.state.u[:n]
    turns = MOMENT_COMPONENTS[dim]  # the angular momentum's components
    angular = A["internal_angular_impulse"][:n].reshape(n, turns)
    defects_at = reduction.add_sums([A["internal_impulse"][:n], angular, sim.state.mass[:n, None] * x,
                                  sim.state.mass[:n] * np.einsum("na,na->n", x, x)])
    terms = {t.key: [(reduction.add_sums(body), len(body)) for body in energies[t.key]] for t in TERMS}
    kinetic_at = reduction.add_sums([columns[b.lo:b.hi, 2:2 + dim] for b in bodies]) if len(bodies) > 1 else 0
    top = reduction.add_max([eta.max() if len(eta) else 0.0])
    shown = [t for t in TERMS if t.shown(sim)]

    def balance(kinetic: Exact, parts: dict) -> Exact:
        out = kinetic
        for t in TERMS:
            out = out + parts[t.key] if t.sign > 0 else out - parts[t.key]
        return out

    def values() -> dict:
        parts = reduction.sums
        weighted, mass, kinetic, momentum, angular = (
            parts[start], parts[start + 1], parts[start + 2:start + 2 + dim],
            parts[start + 2 + dim:start + 2 + 2 * dim], parts[start + 2 + 2 * dim:start + columns.shape[1]])
        per_body = {key: [sum(parts[k:k + size], Exact(0)) for k, size in where] for key, where in terms.items()}
        kinetic = sum(kinetic[1:], kinetic[0])
        whole = {key: sum(values[1:], values[0]) for key, values in per_body.items()}
        out = {"kinetic_energy": float(kinetic)}
        out.update((t.column, float(whole[t.key])) for t in shown)
        out.update(total_energy=float(balance(kinetic, whole)), disorder=math.sqrt(float(weighted) / float(mass)),
                   disorder_max=reduction.maxima[top])
        for a, name in enumerate("xyz"[:dim]):
            out[f"momentum_{name}"] = float(momentum[a])
        if dim == 2:
            out["angular_momentum"] = float(angular[0])
        for a, name in enumerate("xyz" if dim == 3 else ""):
            out[f"angular_momentum_{name}"] = float(angular[a])
        impulse = parts[defects_at:defects_at + dim]
        turned = parts[defects_at + dim:defects_at + dim + turns]
        first = parts[defects_at + dim + turns:defects_at + 2 * dim + turns]
        second = float(parts[defects_at + 2 * dim + turns])
        for a, name in enumerate("xyz"[:dim]):
            out[f"momentum_defect_{name}"] = float(impulse[a])
        if dim == 2:
            out["angular_momentum_defect"] = float(turned[0])
        for a, name in enumerate("xyz" if dim == 3 else ""):
            out[f"angular_momentum_defect_{name}"] = float(turned[a])
        total = float(mass)
        centre = [float(c) / total for c in first]
        out["radius_of_gyration"] = math.sqrt(max(second / total - sum(c * c for c in centre), 0.0))
        if len(bodies) > 1:
            for k, b in enumerate(bodies):
                comps = parts[kinetic_at + k * dim:kinetic_at + (k + 1) * dim]
                kin = sum(comps[1:], comps[0])
                out[f"kinetic_energy.{b.name}"] = float(kin)
                out.update((f"{t.column}.{b.name}", float(per_body[t.key][k])) for t in shown)
                out[f"total_energy.{b.name}"] = float(balance(kin, {key: v[k] for key, v in per_body.items()}))
        return out

    return values


def contact_parts(sim, reduction: RowReduction):
    """The contact's part of the row (parsph.contact): each entry's force on its first body
    from its second, "contact_force_X.FIRST.SECOND", and the closest approach of two
    particles of bodies in contact over the sum of their contact radii,
    "contact_closest" (below 1: they overlap)."""
    contact = sim.interactions.contact
    if contact is None:
        return dict
    dim = sim.state.dim
    forces = [contact.entry_force[k, sim.state.bodies[first].lo:sim.state.bodies[first].hi]
              for k, (first, _) in enumerate(contact.entries)]
    at = reduction.add_sums(forces)
    closest = reduction.add_max([-contact.closest.min() if len(contact.closest) else -1.0])

    def values() -> dict:
        out = {}
        for k, label in enumerate(contact.labels):
            for a, name in enumerate("xyz"[:dim]):
                out[f"contact_force_{name}.{label}"] = float(reduction.sums[at + k * dim + a])
        out["contact_closest"] = -reduction.maxima[closest]
        return out

    return values


def rigid_parts(sim, reduction: RowReduction):
    """Each rigid body's part of the row (parsph.rigid): the contact force on it from the
    other bodies, "rigid_force_X.NAME", and for a freely moving one the torque of those
    forces about its centre of mass, "rigid_torque.NAME" (2D) or "rigid_torque_X.NAME" (3D)."""
    contact = sim.interactions.contact
    rigid = [b for b in sim.state.bodies if b.rigid]
    if contact is None or not rigid:
        return dict
    dim = sim.state.dim
    free = {body.body.index: body for body in sim.conditions.rigid_bodies}
    where = []
    for b in rigid:
        f = contact.force[b.lo:b.hi]
        items = [f]
        if b.index in free and dim > 1:
            r = sim.state.X[b.lo:b.hi] + sim.state.u[b.lo:b.hi] - free[b.index].centre
            items.append(moments(r, f))
        where.append(reduction.add_sums(items))

    def values() -> dict:
        out = {}
        for b, at in zip(rigid, where):
            for a, name in enumerate("xyz"[:dim]):
                out[f"rigid_force_{name}.{b.name}"] = float(reduction.sums[at + a])
            if b.index in free and dim == 2:
                out[f"rigid_torque.{b.name}"] = float(reduction.sums[at + dim])
            elif b.index in free and dim == 3:
                for a, name in enumerate("xyz"):
                    out[f"rigid_torque_{name}.{b.name}"] = float(reduction.sums[at + dim + a])
        return out

    return values


def global_diagnostics(sim) -> dict:
    """Energies, momenta and disorder of all bodies together, and with more than one body
    each body's energies as "NAME.BODY" (collective)."""
    reduction = RowReduction(sim.comm)
    values = global_parts(sim, reduction)
    reduction.reduce()
    return values()


def check_particle_ids(sim) -> None:
    """Debug check (collective): the owned particles of all ranks are exactly the ids
    0..N-1, each once. Compares the count, the sum and the sum of squares of the ids
    (exact integer arithmetic) with those of 0..N-1."""
    from parsph.errors import ParsphError

    gid = sim.state.gid[: sim.state.n_owned].astype(object)
    count, total, squares = (sum(x) for x in zip(*sim.comm.allgather(
        (len(gid), int(gid.sum()), int((gid * gid).sum())))))
    n = sim.state.decomp.total
    expected = (n, n * (n - 1) // 2, (n - 1) * n * (2 * n - 1) // 6)
    if (count, total, squares) != expected:
        raise ParsphError(f"particles lost or duplicated at step {sim.step_count}: ranks own {count} "
                          f"particles, expected {n} (id sums {total}, {squares} vs {expected[1:]})")


def check_finite(values: dict, sim) -> None:
    """Stop the run (collective: `values` are the same global row on every rank) if a
    history value about to be written is not finite, naming the series, the step and the
    particle where the state first leaves the range of double precision: the lowest global
    id whose position, velocity, force or kinetic energy is not finite."""
    from parsph.errors import ParsphError

    bad = [f"{name} = {value}" for name, value in values.items() if not math.isfinite(value)]
    if not bad:
        return
    n = sim.state.n_owned
    v = sim.state.v[:n]
    with np.errstate(over="ignore", invalid="ignore"):
        kinetic = 0.5 * sim.state.mass[:n] * np.einsum("na,na->n", v, v)
        columns = {"position": sim.state.X[:n] + sim.state.u[:n], "velocity": v, "force": sim.state.force[:n],
                   "kinetic energy": kinetic[:, None]}
    mine = []
    for what, column in columns.items():
        rows = np.flatnonzero(~np.isfinite(column).all(axis=1))
        if len(rows):
            k = rows[np.argmin(sim.state.gid[rows])]
            mine.append((int(sim.state.gid[k]), what, tuple(column[k].tolist())))
    found = [c for part in sim.comm.allgather(mine) for c in part]
    where = ""
    if found:
        gid, what, value = min(found)
        where = f"; particle {gid} is the first whose {what} is not finite ({', '.join(f'{c:.3g}' for c in value)})"
    error = ParsphError(
        f"the history row at step {sim.step_count}, t = {sim.t:.6g} s is not finite: "
        f"{', '.join(bad[:4])}{', ...' if len(bad) > 4 else ''}{where}; the run is stopped (the output written "
        "so far is intact): check the initial conditions, loads and material constants for values beyond the "
        "range of double precision (1.8e308)")
    error.agreed = True  # the row is the same global reduction on every rank
    raise error


def history_row(sim, reduction: RowReduction | None = None) -> dict:
    """The history row: clock, diagnostics.global_parts, obstacle forces and probes
    (collective: one reduction over the ranks, `reduction` if given, holding what the
    caller added)."""
    reduction = reduction or RowReduction(sim.comm)
    energies = global_parts(sim, reduction)
    walls = reduction.add_sums(sim.walls.contacts)  # obstacle-major, then component
    torques = reduction.add_sums(sim.walls.torques)  # surface-major, then component
    contact = contact_parts(sim, reduction)
    others = sim.interactions.columns(sim.state, reduction)
    rigid = rigid_parts(sim, reduction)
    probes = probe_parts(sim.scene.probes, sim, reduction)
    reduction.reduce()
    out = {"time": sim.t, "step": float(sim.step_count), "dt": sim.stable.dt,
           "reference_updates": float(sim.topology.count)}
    out.update(energies())
    for k, label in enumerate(sim.walls.names):
        for a, name in enumerate("xyz"[: sim.state.dim]):
            out[f"{label}_force_{name}"] = float(reduction.sums[walls + k * sim.state.dim + a])
    axes = "z" if sim.state.dim == 2 else "xyz"
    for j, k in enumerate(sim.walls.turning):
        for a, name in enumerate(axes):
            out[f"{sim.walls.names[k]}_torque_{name}"] = float(reduction.sums[torques + j * len(axes) + a])
    out.update(contact())
    for values in others:
        out.update(values())
    out.update(rigid())
    out.update(probes())
    return out
