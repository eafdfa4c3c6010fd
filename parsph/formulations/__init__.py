"""The formulations, the registry: what a scene's `formulation.type` names. Each family's
class declares the types it serves, resolves and checks their keys and bodies, builds its
relations and its stages (formulations.nodal: corrected, symmetrised SPH and RLM;
formulations.galerkin: KBM and EFG)."""

from parsph.formulations import base
from parsph.formulations.galerkin import GalerkinFormulation
from parsph.formulations.nodal import NodalFormulation

FAMILIES = (NodalFormulation, GalerkinFormulation)
FORMULATIONS = {name: family for family in FAMILIES for name in family.TYPES}
FORMULATION_KEYS = {**base.KEYS, **{k: key for family in FAMILIES for k, key in family.KEYS.items()}}
