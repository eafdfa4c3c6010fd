"""Kernel relations: the particle pairs of a group of bodies that share a kernel (its type),
a Hessian stabilisation (eta and its correction [V eq. 17, 21]) and, for the bodies whose
reference moves (ulsph, the Eulerian kernel), one schedule of reference updates
(update_every, update_strain) and one rule for keeping their lists between searches
(search_every, skin: relations.Skin). The bodies of a scene form as few groups as they can,
in body order; most scenes are one group.

Each relation holds its pairs as one ReferenceData (formulations.reference) over all the
rank's owned rows, those of the other groups' bodies left empty: pairs never join two
bodies, so a stage of body b reads `b.relation.ref` over its rows b.lo..b.hi exactly as it
would read the reference data of a scene of b alone. A relation is built once (a
total-Lagrangian group) or again at each of its reference updates (`build`); it never
evaluates forces.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from mpi4py import MPI

from parsph import config
from parsph.formulations import reference
from parsph.relations import Skin


@dataclass
class Configuration:
    """The local particles a relation is built in: positions, d-dimensional measures and
    volumes (of the reference: X or X^r), supports, global ids, body indices; rows
    0..n_owned-1 owned, rows up to n_rows built for the reverse coefficients."""

    X: np.ndarray
    measure: np.ndarray
    volume: np.ndarray
    support: np.ndarray
    gid: np.ndarray
    body: np.ndarray
    n_owned: int
    n_rows: int


class KernelRelation:
    """The kernel pairs of `bodies` (state.Body, one kernel type, eta, hessian_correction and
    update schedule), with their rebuild policy: once, or at each update of their reference
    by count (`every` steps) or strain (`strain`), searched at most every `rule.every` updates
    with lists `skin` wider (the Skin rule of `length` beyond the reach) and otherwise rebuilt
    on the kept lists. `count`: its reference updates so far, `since`: steps since the last."""

    def __init__(self, index: int, bodies: list, scene_bodies: list, scene: config.Scene, length: float, comm):
        self.index, self.bodies = index, bodies
        specs = scene.bodies
        self.kernel = config.kernel_of(scene, specs[bodies[0].index]).type
        forms = [b.formulation for b in bodies]
        self.eta = max(f.eta for f in forms)
        self.weighted_hessian = next((f.weighted_hessian for f in forms if f.eta > 0), True)
        moving = [b for b in bodies if b.moves]
        self.moves = bool(moving)  # the reference of some of its bodies moves
        self.eulerian = any(b.formulation.eulerian for b in moving)  # inside every step
        schedule = (moving or bodies)[0]
        self.every, self.strain = schedule.formulation.update_every, schedule.formulation.update_strain
        kept = specs[schedule.index].formulation
        self.rule = Skin(config.skin(kept) * length, comm, config.search_every(kept))
        self.skin = 0.0  # the skin of the current lists (none at set-up: the first update searches)
        self.count = 0
        self.since = 0
        self.whole = len(bodies) == len(scene_bodies)  # it holds every body of the scene
        self.options = [b.formulation.pair_options if b in bodies else None for b in scene_bodies]
        self.ref = None
        for b in bodies:
            b.relation = self

    def build(self, at: Configuration, search: bool = True, detached: np.ndarray | None = None,
              cut: np.ndarray | None = None, tolerant: bool = False) -> reference.ReferenceData:
        """Its reference data in configuration `at`: searched (with the skin, if its
        reference moves), or (`search` False) rebuilt on the lists kept at the last search;
        without the pairs of the `detached` particles and the `cut` ones, the singular rows
        listed rather than raised if `tolerant` (formulations.reference.build)."""
        self.ref = reference.build(
            at.X, at.measure, at.volume, at.support, at.gid, at.n_owned, at.n_rows, self.kernel, at.body,
            self.options, self.eta, self.weighted_hessian, skin=self.skin if search and self.moves else None,
            kept=None if search else self.ref.kept, detached=detached, cut=cut, tolerant=tolerant)
        return self.ref

    def due(self, strain: float | None = None) -> bool:
        """Whether its reference update is due between steps: by count, or (given the
        largest incremental log strain of its bodies) by strain. An Eulerian kernel moves
        inside its steps."""
        if not self.moves or self.eulerian:
            return False
        if strain is None:
            return bool(self.every) and self.since >= self.every
        return bool(self.strain) and strain > self.strain

    def rows(self, state) -> np.ndarray | None:
        """Its bodies' rows of the owned points of the particles and then each other set
        (None: all of them, it holds every body)."""
        if self.whole:
            return None
        rows, start = [], 0
        for points in state.point_sets():
            for b in self.bodies:
                lo, hi = (b.lo, b.hi) if points is state.particles else b.set_rows[points.name]
                rows.append(np.arange(start + lo, start + hi))
            start += points.n_owned
        return np.concatenate(rows)


def groups(bodies: list, scene: config.Scene) -> list:
    """The bodies in as few groups as they go (in body order, each body in the first group it
    fits): one kernel type; one eta and hessian_correction among the stabilised bodies; one
    update schedule and list rule among the bodies whose reference moves."""
    specs = scene.bodies

    def key(b):
        form, spec = b.formulation, specs[b.index].formulation
        stabilised = (form.eta, form.weighted_hessian) if form.eta > 0 else None
        schedule = (form.eulerian, form.update_every, form.update_strain, config.search_every(spec),
                    config.skin(spec)) if b.moves else None
        return config.kernel_of(scene, specs[b.index]).type, stabilised, schedule

    def fits(a, b):
        return a[0] == b[0] and all(None in (x, y) or x == y for x, y in zip(a[1:], b[1:]))

    out = []
    for b in bodies:
        group = next((g for g in out if all(fits(key(b), key(other)) for other in g)), None)
        if group is None:
            out.append([b])
        else:
            group.append(b)
    return out


def reach(support: np.ndarray, comm) -> float:
    """The largest support over all ranks: the unit of the skins."""
    return comm.allreduce(float(support.max()) if len(support) else 0.0, op=MPI.MAX)
