"""Essential boundary conditions on non-interpolating shape functions, by boundary
collocation: the explicit form of the transformation method (Chen & Wang 2000; [R] leaves
the technique open).

The MLS shape functions of EFG do not pass through the particle values: the velocity at a
particle is v^h(X_I) = sum_J Phi_J(X_I) v_J, not v_I. After the loop has written the
prescribed values into the constrained components (bc.BoundaryConditions), those
components' particle values are replaced, component by component, by the solution of

    sum_{J in B} Phi_J(X_I) v_J = vbar_I - sum_{J not in B} Phi_J(X_I) v_J,      I in B,

B the constrained particles of EFG bodies, so that the approximation itself takes the
prescribed value at every constrained particle. Velocities are collocated for every
condition; displacements for the ones that prescribe the displacement (fixed, displacement:
under a velocity condition the displacement follows by integration). The matrix's rows are
gathered from all ranks in global-id order and factorised the same way on every rank, once
per set of active conditions (Lagrangian kernel) or per step (Eulerian kernel); each time the
right-hand sides are gathered in the same order and every rank solves the same system, so
the result does not depend on the number of ranks.
"""

from __future__ import annotations

import numpy as np

from parsph.errors import InputError
from parsph.parallel.runtime import collective


def collocated(formulation) -> bool:
    """Whether a body's constraints are collocated: EFG (MLS shape functions with a linear
    basis). Not KBM: its corrected gradients are exact for linear particle data, but its
    Shepard functions reproduce only constants, so collocating them moves the clamped
    particles off a linear field (measured on the cantilever at n = 16: energy-norm error
    0.083 instead of 0.017); its constraints act on the particle values."""
    return formulation.collocates


class _System:
    """One component's collocation system: the owned constrained rows, and the factorised
    matrix of all ranks' rows in global-id order."""

    def __init__(self, comm, gid, rows, segments, component):
        self.component = component
        self.rows = rows  # owned particles constrained in this component
        gathered = comm.allgather(gid[rows])
        everyone = np.concatenate(gathered)
        self.size = len(everyone)
        order = np.argsort(everyone, kind="stable")
        position = np.empty(self.size, np.int64)
        position[order] = np.arange(self.size)
        self.position = position  # global row of each gathered entry, in rank order
        start = sum(len(g) for g in gathered[: comm.rank])
        self.mine = position[start: start + len(rows)]
        if not self.size:
            return
        sorted_gids = everyone[order]
        in_b = np.isin(gid, sorted_gids)
        constrained = np.zeros(len(gid), bool)
        constrained[rows] = True
        row, col, phi = [np.zeros(0, np.int64)], [np.zeros(0, np.int64)], [np.zeros(0)]
        for lo, hi, ptr, idx, values in segments:  # each body's pairs of the constrained rows
            of_pair = np.repeat(np.arange(len(ptr) - 1), np.diff(ptr))
            take = constrained[of_pair] & (of_pair >= lo) & (of_pair < hi)
            row.append(of_pair[take])
            col.append(idx[take])
            phi.append(values[take])
        row, col, phi = np.concatenate(row), np.concatenate(col), np.concatenate(phi)
        inside = in_b[col]
        # the known part: pairs with a column outside B, summed per row in pair order
        self.known_row = np.searchsorted(rows, row[~inside])
        self.known_col = col[~inside]
        self.known_phi = phi[~inside]
        entries = comm.allgather((gid[row[inside]], gid[col[inside]], phi[inside]))
        r = np.concatenate([e[0] for e in entries])
        c = np.concatenate([e[1] for e in entries])
        values = np.concatenate([e[2] for e in entries])
        from scipy.sparse import csc_matrix  # here: scipy.sparse takes 0.05 s to import
        from scipy.sparse.linalg import splu

        matrix = csc_matrix((values, (np.searchsorted(sorted_gids, r), np.searchsorted(sorted_gids, c))),
                            shape=(self.size, self.size))
        matrix.sort_indices()  # the same storage whatever order the ranks' rows came in
        try:
            self.lu = splu(matrix)
        except RuntimeError:
            self.lu = None
        diagonal = np.abs(self.lu.U.diagonal()) if self.lu is not None else np.zeros(1)
        if self.lu is None or not diagonal.min() > 1e-12 * diagonal.max():
            raise InputError(
                f"the collocation matrix of the constrained particles (component {component}, {self.size} "
                "particles) is singular: the boundary condition's group holds particles whose shape functions "
                "cannot take independent values; constrain fewer particles or increase kernel.support")

    def apply(self, comm, y):
        """Replace the owned constrained entries of column `component` of y (owned and
        ghost rows current) by the collocated values; y[rows] holds the prescribed ones."""
        if not self.size:
            return
        k = self.component
        rhs = y[self.rows, k] - np.bincount(self.known_row, self.known_phi * y[self.known_col, k],
                                            len(self.rows))
        full = np.empty(self.size)
        full[self.position] = np.concatenate(comm.allgather(rhs))
        y[self.rows, k] = self.lu.solve(full)[self.mine]


class BoundaryCollocation:
    """The collocated constraints `bcs` (bc.BoundaryConditions) of the EFG bodies of a rank's
    particles (`state`: state.RankState)."""

    def __init__(self, state, bcs):
        self.state, self.bcs = state, bcs
        self.segments = [(b.lo, b.hi, *b.formulation.trial_functions()) for b in state.bodies if collocated(b.formulation)]
        self.efg = np.zeros(state.n_owned, bool)  # particles of EFG bodies
        self.lagrangian = np.zeros(state.n_owned, bool)  # ... whose kernel is Lagrangian
        for b in state.bodies:
            if collocated(b.formulation):
                self.efg[b.lo:b.hi] = True
                self.lagrangian[b.lo:b.hi] = not b.formulation.updated
        self._systems = {}

    def _for(self, active: tuple, kinds: tuple) -> list:
        key = (active, kinds)
        if key not in self._systems:
            state = self.state
            mask = np.zeros((state.n_owned, state.dim), bool)
            for k in active:
                item = self.bcs.items[k]
                if item.kind in kinds:
                    mask[item.rows, item.cols] = True
            mask &= (self.efg if "velocity" in kinds else self.lagrangian)[:, None]
            with collective(state.comm):
                self._systems[key] = [_System(state.comm, state.gid, np.flatnonzero(mask[:, c]), self.segments, c)
                                      for c in range(state.dim)]
        return self._systems[key]

    def velocity(self, t: float) -> None:
        """Collocate the velocities of the conditions active at t."""
        self._apply(self.state.v, "v", t, ("fixed", "velocity", "displacement"))

    def displacement(self, t: float) -> None:
        """Collocate the displacements of the fixed and displacement conditions active at t
        (Lagrangian kernel; with the Eulerian one, Phi is that of the current configuration
        and the displacement follows from the collocated velocities)."""
        self._apply(self.state.u, "u", t, ("fixed", "displacement"))

    def _apply(self, y, name, t, kinds):
        systems = [s for s in self._for(self.bcs.active_items(t), kinds) if s.size]
        if systems:
            self.state.particles.refresh(name)
            for system in systems:
                system.apply(self.state.comm, y)
