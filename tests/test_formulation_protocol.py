"""The formulation protocol (formulations.base.Formulation): the rest of the code reads a
body's formulation only through the members the protocol declares, for every family and
the options that switch members on (hourglass control, viscosity, an updated reference, an
Eulerian kernel, collocated constraints); a family has no member it fakes."""

from __future__ import annotations

import numpy as np
import pytest

import parsph.state
from parsph.formulations import FORMULATIONS
from parsph.formulations.base import Formulation
from physics import simulation


class Recording:
    """A formulation whose members read (or set) from outside it are recorded in `seen`."""

    def __init__(self, formulation, seen: set):
        object.__setattr__(self, "_formulation", formulation)
        object.__setattr__(self, "_seen", seen)

    def __getattr__(self, name):
        self._seen.add(name)
        return getattr(self._formulation, name)

    def __setattr__(self, name, value):
        self._seen.add(name)
        setattr(self._formulation, name, value)


@pytest.mark.parametrize("overrides", [
    ["formulation.hourglass_form='paper'", "formulation.viscosity=1.0"],
    ["formulation.type='ulsph'", "formulation.update_every=5", "formulation.hessian=0.5"],
    ["formulation.type='kbm'"],
    ["formulation.type='efg'", "formulation.kernel='eulerian'"],
], ids=["tlsph", "ulsph", "kbm", "efg_eulerian"])
def test_the_code_reads_formulations_through_the_protocol_only(monkeypatch, overrides):
    seen = set()
    monkeypatch.setattr(parsph.state, "FORMULATIONS", {
        name: (lambda *args, family=family, **kwargs: Recording(family(*args, **kwargs), seen))
        for name, family in FORMULATIONS.items()})
    sim = simulation("cantilever", ["time.end=1e-3", *overrides])
    u = sim.state.u[:sim.state.n_owned].copy()
    for _ in range(6):
        sim.step()
    sim.diagnostics()
    assert np.abs(sim.state.u[:sim.state.n_owned] - u).max() > 0.0  # it moved
    assert {"build", "stages", "stable_step", "integrated", "updated"} <= seen  # it was read
    undeclared = {name for name in seen if not hasattr(Formulation, name)} - set(Formulation.__annotations__)
    assert not undeclared, f"members read outside the formulation but not in its protocol: {sorted(undeclared)}"


def test_no_family_redefines_an_option_it_does_not_have():
    """A family sets the options of features it has; the others keep the protocol's
    defaults (no hourglass control, stabilisation or viscosity in the Galerkin methods)."""
    galerkin = FORMULATIONS["kbm"]
    nodal_only = ("eta", "weighted_hessian", "hourglass_form", "alpha", "viscous", "update_strain",
                  "absorbs_hourglass_work", "hourglass_penalty")
    assert not [name for name in nodal_only if name in vars(galerkin)]
    for family in set(FORMULATIONS.values()):
        assert issubclass(family, Formulation)
        for name in ("stages", "quadrature", "integrated", "pair_options"):  # stable_step: the base's, shared
            assert getattr(family, name) is not getattr(Formulation, name), (family.__name__, name)
