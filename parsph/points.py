"""Point sets: one rank's points of one kind, with the arrays they carry.

Particles are a point set: they carry mass and the degrees of freedom. Integration points
that carry no mass (stress points, Gauss points) are point sets of their own. A point set
holds its owned points in global-id order, then its ghosts (and mirror images), the arrays
of the registered fields it carries (parsph.fields) and the work arrays of its formulation,
by name, and its halo plan (parallel.decomposition.Decomposition). What migrates with a
point and what a checkpoint stores follow from the field registry; ghost values are
refreshed by name.
"""

from __future__ import annotations

import numpy as np

from parsph import fields


class PointSet:
    def __init__(self, name: str, gid: np.ndarray, n_owned: int, decomp, carried: list, arrays: dict):
        """`carried`: the registered fields the set carries; `arrays`: every array by name
        (carried fields and work arrays; aliases allowed), rows: owned, then ghosts."""
        self.name = name
        self.gid = gid
        self.n_owned = n_owned
        self.decomp = decomp
        self.carried = carried
        self.arrays = dict(arrays, gid=gid)
        # its material states: committed as NAME, the last evaluation's as NAME_trial
        self.states = [name for name in carried if fields.get(name, self.name).kind == "state"]

    @property
    def total(self) -> int:
        """Points of the set over all ranks."""
        return self.decomp.total

    def owned(self, name: str) -> np.ndarray:
        """The owned points' values of array `name`."""
        return self.arrays[name][: self.n_owned]

    def migrating(self) -> dict:
        """The owned points' carried fields that travel with them (with "gid")."""
        return {name: self.owned(name) for name in fields.migrating(self.carried, self.name)}

    def checkpointed(self) -> dict:
        """The owned points' carried fields a checkpoint stores (the global ids are the rows)."""
        return {name: self.owned(name) for name in fields.checkpointed(self.carried, self.name) if name != "gid"}

    def refresh(self, *names: str) -> None:
        """Copy the owners' values of the named arrays into the ghost rows, and into the
        mirror images' rows reflected, but a material state (NAME or NAME_trial) as it is:
        its columns are not components of one vector or tensor."""
        self.decomp.refresh(*(self.arrays[name] for name in names),
                            copied=[name.removesuffix("_trial") in self.states for name in names])

    def refresh_all(self, *names: str) -> None:
        """Copy the owners' values of the named carried fields into the rows of both ghost
        layers and of the mirror images of both, reflected as their kinds say: the rows a
        search would make, between searches (Decomposition.refresh_all)."""
        self.decomp.refresh_all(*(self.arrays[name] for name in names),
                                fields=[fields.get(name, self.name) for name in names])

    def commit(self) -> None:
        """The material state of the last stress evaluation (the fields NAME_trial) becomes
        the committed state of the owned points."""
        for name in self.states:
            self.owned(name)[:] = self.owned(name + "_trial")
