"""Scene files: TOML schema, defaults, validation and `--set` overrides.

A scene is read with the standard library's `tomllib`, checked against the Key tables below
and resolved: every default filled in. The solver reads the resolved scene typed (`Scene`:
a frozen section per table, `scene.time.cfl`, and a tuple of typed entries per array of
tables, `scene.walls[0].normal`, their classes made from the Key tables by
parsph.sections); every output file stores it as the nested table (`Scene.as_dict`,
`to_json`). Any problem is an `InputError` whose message names the key
(`material.density`, `bc[1].group`, ...).
"""

from __future__ import annotations

import ast
import copy
import dataclasses
import difflib
import operator
import json
import math
import os
import re
import stat
import sys
import tomllib
from dataclasses import make_dataclass
from typing import Any

from parsph import expressions, quantities, surfaces, ties
from parsph.errors import InputError
from parsph.keys import REQUIRED, Key, greater_than, in_range, non_negative, one_of, positive
from parsph.formulations import FAMILIES, FORMULATION_KEYS, FORMULATIONS
from parsph.sections import section as section_type
from parsph.materials import FAILURE_KEYS, LAW_KEYS, LAWS, check_failure, constants, failure_of

KERNELS = ("cubic_spline", "wendland_c2", "spiky")
MATERIALS = tuple(LAWS)


def snapshot_fields(v):
    """names of particle quantities (those of probes.quantity, and rank, reference_position,
    cauchy_stress, body, ...), position among them"""
    known = quantities.snapshot_names()
    unknown = [f for f in v if f not in known]
    if unknown:
        return f"has unknown field(s) {unknown}; choose from {', '.join(known)}"
    return None if "position" in v else "must include 'position' (the snapshot geometry)"


def probe_quantity(v):
    """the name of a scalar or vector particle quantity (displacement, velocity, von_mises,
    plastic_strain, ...)"""
    known = quantities.probe_names()
    return None if v in known else f"must be one of {', '.join(map(repr, known))}"


SECTIONS: dict[str, dict[str, Key]] = {
    "scene": {
        "name": Key("str", REQUIRED, doc="short name of the scene"),
        "dimension": Key("int", REQUIRED, one_of(1, 2, 3), "1, 2 (plane strain) or 3"),
        "description": Key("str", "", doc="what the scene is, in a sentence or two"),
        "source": Key("str", "", doc="paper and section the scene reproduces"),
        "expected": Key("str", "", doc="the outcome the scene must show"),
    },
    "geometry": {
        "parts": Key("table", REQUIRED, doc="array of shapes, united"),
        "thickness": Key("float", 1.0, positive, "out-of-plane thickness in 2D [m]"),
        "area": Key("float", 1.0, positive, "cross-section area in 1D [m^2]"),
    },
    "kernel": {
        "type": Key("str", "wendland_c2", one_of(*KERNELS), "the kernel function W"),
        "support": Key("float", 2.1, positive, "support radius / particle spacing"),
        "neighbours": Key("int", 0, non_negative, "if > 0: per-particle support for this many neighbours"),
    },
    "material": {
        "model": Key("str", REQUIRED, one_of(*MATERIALS),
                      "the material law; its constants: parsph keys material.MODEL"),
        "density": Key("float", REQUIRED, positive, "reference density [kg/m^3]"),
        **LAW_KEYS,  # each law's constants (materials.LAWS)
        **FAILURE_KEYS,  # the failure models' (materials.FAILURES)
        "break_pairs": Key("bool", False, None,
                           "with a failure model: a failed particle (damage 1) loses its pairs, so that cracks "
                           "open and the failed particles fly free (default: they keep them, as [G §4.6])"),
    },
    "formulation": {
        "type": Key("str", "tlsph", one_of(*FORMULATIONS), "; ".join(
            f"{name}: {doc}" for family in FAMILIES for name, doc in family.TYPES.items())),
        **FORMULATION_KEYS,  # the formulation families' (formulations.FORMULATIONS)
    },
    "time": {
        "end": Key("float", REQUIRED, positive, "end time [s]"),
        "dt": Key("float", 0.0, non_negative, "fixed time step [s]; 0 = from the CFL condition"),
        "cfl": Key("float", 0.85, in_range(0.0, 1.0, True), "safety factor of the CFL time step"),
        "damping": Key("float", 0.0, non_negative, "mass-proportional damping rate [1/s]"),
        "max_steps": Key("int", 0, non_negative, "stop after this many steps (0 = no limit)"),
        "step_floor": Key("float", 1e-6, in_range(0.0, 1.0, False, True),
                          "stop with an error naming the particle (and the bodies, in contact) when the stable "
                          "step falls below this fraction of the run's first one: the step has collapsed "
                          "(0 = never)"),
        "wall_limit": Key("float", 0.0, non_negative,
                          "wall-clock seconds after which the run checkpoints and stops (0 = none)"),
    },
    "balance": {
        "energy": Key("float", None, non_negative,
                      "warn when the total energy drifts by more than this fraction of the largest energy "
                      "the run has held (0 = no check; default 0.05, or 0.25 for a scene with a body in kbm "
                      "or rlm, whose forces are not the gradient of their energy)"),
        "momentum": Key("float", 1e-3, non_negative,
                        "warn when the forces between particles change the momentum by more than this "
                        "fraction of sqrt(2 M E) (M the mass, E the largest energy), or the angular momentum "
                        "by more than it times the radius of gyration (0 = no check)"),
        "strict": Key("bool", False, None, "stop the run (exit 1, after a checkpoint) instead of warning"),
    },
    "parallel": {
        "rebalance": Key("float", 0.0, non_negative,
                         "at a reference update, re-decide ownership when the busiest rank's work "
                         "exceeds the mean by this fraction (0 = at every update)"),
    },
    "loads": {
        "body_acceleration": Key("vector", None, doc="uniform body force per unit mass [m/s^2]"),
    },
    "output": {
        "history_interval": Key("float", 0.0, non_negative, "simulated time between history rows; 0 = every history_every steps"),
        "history_every": Key("int", 10, positive, "steps between history rows if history_interval is 0"),
        "snapshot_interval": Key("float", 0.0, non_negative, "simulated time between snapshots; 0 = none but the last"),
        "snapshot_fields": Key("strlist", ["position", "displacement", "velocity", "J", "von_mises", "rank"],
                              snapshot_fields, "the particle fields each snapshot holds"),
        "progress_seconds": Key("float", 5.0, positive, "seconds between progress lines when not on a terminal"),
        "checkpoint_interval": Key("float", 0.0, non_negative, "simulated time between checkpoints (0 = none)"),
        "checkpoint_every": Key("int", 0, non_negative, "steps between checkpoints (0 = none)"),
        "checkpoint_keep": Key("int", 2, positive, "how many of the newest checkpoints to keep"),
    },
}

# Shapes of geometry.parts and the keys each one takes.
PART_KEYS: dict[str, dict[str, Key]] = {
    "box": {
        "lower": Key("vector", REQUIRED, doc="lower corner [m]"),
        "upper": Key("vector", REQUIRED, doc="upper corner [m]"),
        "spacing": Key("float", REQUIRED, positive, "lattice spacing; the box's sides are multiples of it [m]"),
        "placement": Key("str", "cell", one_of("cell", "node"),
                         "cell: a particle at each cell's centre; node: at the cells' corners, the "
                         "boundary's volumes halved per axis on the boundary"),
    },
    "random_patch": {  # Voronoi particles (random points, then Lloyd's relaxation)
        "lower": Key("vector", REQUIRED, doc="lower corner [m]"),
        "upper": Key("vector", REQUIRED, doc="upper corner [m]"),
        "count": Key("int", REQUIRED, positive, "number of particles"),
        "seed": Key("int", 0, doc="seed of the random points"),
        "lloyd_iterations": Key("int", 20, non_negative, "Lloyd's relaxations: each moves the points to the "
                                                        "centroids of their Voronoi cells"),
    },
    "cylinder": {
        "base_center": Key("vector", REQUIRED, doc="centre of the base [m]"),
        "radius": Key("float", REQUIRED, positive, "radius [m]"),
        "length": Key("float", REQUIRED, positive, "length along the axis [m]"),
        "spacing": Key("float", REQUIRED, positive, "spacing of the cubic lattice [m]"),
        "axis": Key("int", 2, one_of(0, 1, 2), "the cylinder's axis (0 = x, 1 = y, 2 = z)"),
    },
    "ring": {  # particles on concentric circles
        "center": Key("vector", REQUIRED, doc="centre [m]"), "inner_radius": Key("float", REQUIRED, positive, "inner radius [m]"),
        "outer_radius": Key("float", REQUIRED, positive, "outer radius [m]"),
        "spacing": Key("float", REQUIRED, positive, "distance between the circles and along them [m]"),
    },
    "disk": {  # particles on concentric circles
        "center": Key("vector", REQUIRED, doc="centre [m]"), "radius": Key("float", REQUIRED, positive, "radius [m]"),
        "spacing": Key("float", REQUIRED, positive, "distance between the circles and along them [m]"),
    },
    "polar_ring": {  # a polar lattice: particles on both surfaces (KBM's stress points on a ring)
        "center": Key("vector", REQUIRED, doc="centre [m]"), "inner_radius": Key("float", REQUIRED, positive, "inner radius [m]"),
        "outer_radius": Key("float", REQUIRED, positive, "outer radius [m]"),
        "radial": Key("int", REQUIRED, positive, "rows of particles, from the inner to the outer surface"),
        "angular": Key("int", REQUIRED, positive, "particles per row"),
    },
    "mesh": {  # a finite-element mesh: a particle per element (geometry.mesh_parts)
        "file": Key("str", REQUIRED, doc="the mesh file (Gmsh .msh, Abaqus .inp, VTK .vtu, ... as meshio reads "
                                         "them), relative to the scene file's directory: a particle at each "
                                         "element's centroid with its volume"),
        "scale": Key("float", 1.0, positive, "factor on the mesh's coordinates (1e-3 for a mesh in mm)"),
        "translate": Key("vector", None, doc="added to the scaled, mirrored and rotated coordinates [m]"),
        "cells": Key("strlist", None, doc="only the elements of these mesh sets (default: all the elements of "
                                          "the scene's dimension)"),
    },
}
# Solid parts (geometry.solids), filled with a cell-centred lattice (geometry.fill): a part's
# transforms, and its spacing (not in a boolean's parts, which the boolean's spacing fills).
TRANSFORM_KEYS = {
    "scale": Key("value", None, doc="scale factor, a number or one per axis (applied first)"),
    "mirror": Key("value", None, doc="reflect: an axis (0 = x, 1 = y, 2 = z) or a list of axes (after scale)"),
    "rotate": Key("value", None, doc="rotate (after mirror): in 2D an angle in degrees, counter-clockwise; in 3D a "
                                     "rotation vector [x, y, z], the axis times the angle in degrees"),
    "translate": Key("vector", None, doc="move by this vector (applied last) [m]"),
}
FILL_KEYS = {
    "spacing": Key("float", None, positive, "spacing of the cell-centred lattice that fills the solid; required, "
                                            "except in a boolean's parts [m]"),
    "pack": Key("bool", False, None, "relax the particles within 3 spacings of the boundary (repulsion, kept half "
                                     "a spacing inside) so the boundary is smooth, not a staircase; same count "
                                     "and volumes"),
    "pack_iterations": Key("int", 20, positive, "relaxation steps of pack"),
}
OUTLINE_KEYS = {
    "vertices": Key("matrix", None, doc="the outline's vertices [[x, y], ...], either way round [m]"),
    "holes": Key("value", None, doc="the holes' outlines, a list of vertex lists [[[x, y], ...], ...] [m]"),
    "file": Key("str", None, doc="instead of vertices: an outline file, .csv (x,y lines), .dxf or .svg (its "
                                 "closed outlines, holes included), relative to the scene file"),
}
SOLID_KEYS: dict[str, dict[str, Key]] = {
    "polygon": {**OUTLINE_KEYS},
    "circle": {"center": Key("vector", REQUIRED, doc="centre [m]"),
               "radius": Key("float", REQUIRED, positive, "radius; the area is exactly pi r^2 [m]")},
    "sphere": {"center": Key("vector", REQUIRED, doc="centre [m]"),
               "radius": Key("float", REQUIRED, positive, "radius [m]")},
    "cone": {"base_center": Key("vector", REQUIRED, doc="centre of the base [m]"),
             "axis": Key("vector", [0.0, 0.0, 1.0], doc="direction from the base to the top"),
             "length": Key("float", REQUIRED, positive, "height along the axis [m]"),
             "radius": Key("float", REQUIRED, positive, "radius of the base [m]"),
             "top_radius": Key("float", 0.0, non_negative, "radius of the top: 0 a cone, else a frustum [m]")},
    "extrusion": {**OUTLINE_KEYS,
                  "z0": Key("float", 0.0, doc="the outline's plane z = z0 [m]"),
                  "length": Key("float", REQUIRED, positive, "extruded length along +z [m]")},
    "surface": {"file": Key("str", REQUIRED, doc="a closed triangle mesh (.stl, .obj, .ply) relative to the scene "
                                                 "file; inside: generalised winding number > 1/2")},
    **{kind: {"parts": Key("table", REQUIRED, doc=f"the solids {how}: a list of tables [{{shape = ...}}, ...] "
                                                   "(solid shapes, without spacing)")}
       for kind, how in (("union", "united"), ("difference", "the first minus the others"),
                         ("intersection", "intersected"))},
}
PART_KEYS["mesh"].update({k: TRANSFORM_KEYS[k] for k in ("mirror", "rotate")})
SOLIDS = tuple(SOLID_KEYS)
for _shape, _keys in SOLID_KEYS.items():
    PART_KEYS[_shape] = {**_keys, **FILL_KEYS, **TRANSFORM_KEYS}
PART_DIMENSIONS = {"box": (1, 2, 3), "random_patch": (2,), "cylinder": (3,), "ring": (2,), "disk": (2,),
                   "polar_ring": (2,), "mesh": (2, 3), "polygon": (2,), "circle": (2,), "sphere": (3,),
                   "cone": (3,), "extrusion": (3,), "surface": (3,), "union": (2, 3), "difference": (2, 3),
                   "intersection": (2, 3)}

BC_KEYS = {
    "type": Key("str", REQUIRED, one_of("fixed", "velocity", "displacement"),
                "fixed: held at rest; velocity: moved at value; displacement: moved to value"),
    "group": Key("str", REQUIRED, doc="the particles it holds"),
    "value": Key("vector", None, doc="velocity [m/s] or final displacement [m]"),
    "expression": Key("strlist", None, doc="instead of value: one expression of the reference position "
                                           "x, y, z and the parameters per component"),
    "components": Key("intlist", None, doc="constrained components (default: all)"),
    "ramp": Key("float", 0.0, non_negative, "time over which the value ramps up from 0 [s]"),
    "duration": Key("float", None, positive, "the condition acts for t < duration, then releases the "
                                             "group (default: for ever) [s]"),
}
TRACTION_KEYS = {
    "group": Key("str", REQUIRED, doc="the particles on the loaded surface"),
    "value": Key("vector", None, doc="traction [Pa]"),
    "expression": Key("strlist", None, doc="instead of value: one expression of the reference position "
                                           "x, y, z and the parameters per component [Pa]"),
    "ramp": Key("float", 0.0, non_negative, "time over which the traction ramps up from 0 [s]"),
    "duration": Key("float", None, positive, "the traction acts for t < duration (default: for ever) [s]"),
    "decay": Key("float", None, positive, "time constant tau of a factor exp(-t / tau) (default: none) [s]"),
    "area": Key("float", None, positive, "surface each particle of the group carries [m^2] (default: its "
                                         "measure^((d-1)/d) times the thickness, a lattice's face)"),
}
WALL_KEYS = {
    "group": Key("str", "all", doc="particles that can touch the wall"),
    "point": Key("vector", REQUIRED, doc="a point of the plane at t = 0 [m]"),
    "normal": Key("vector", REQUIRED, doc="normal pointing into the material"),
    "velocity": Key("vector", None, doc="the wall's prescribed velocity [m/s] (default at rest)"),
    "lower": Key("vector", None, doc="with upper: the box of current positions where the wall acts [m]"),
    "upper": Key("vector", None, doc="with lower: the box's upper corner [m]"),
}
TOOL_KEYS = {
    "group": Key("str", "all", doc="particles that can touch the tool"),
    "lower": Key("vector", REQUIRED, doc="lower corner of the tool's box at t = 0 [m]"),
    "upper": Key("vector", REQUIRED, doc="upper corner of the tool's box at t = 0 [m]"),
    "radius": Key("float", 0.0, non_negative, "radius of the rounded edges [m]"),
    "velocity": Key("vector", None, doc="the tool's prescribed velocity [m/s] (default at rest)"),
}
SURFACE_KEYS = {
    "file": Key("str", REQUIRED, doc="the surface file, relative to the scene file: in 3D a triangle mesh (STL, OBJ, "
                                     "PLY, ...; outside: the side its normals face), in 2D a closed outline (CSV of "
                                     "its vertices x, y in order, or DXF) (parsph.surfaces)"),
    "group": Key("str", "all", doc="particles that can touch the surface"),
    "scale": Key("float", 1.0, positive, "factor on the file's coordinates"),
    "rotate": Key("vector", None, doc="rotation of the scaled surface: [angle] in 2D, counter-clockwise; in 3D "
                                      "the rotation vector [x, y, z], the axis times the angle [degrees]"),
    "translate": Key("vector", None, doc="translation of the scaled, rotated surface to its place at t = 0 [m]"),
    "center": Key("vector", None, doc="the point about which it turns, at t = 0, and of its torque (default the "
                                      "middle of its bounding box) [m]"),
    "velocity": Key("vector", None, doc="velocity of the centre [m/s] (default at rest)"),
    "velocity_expression": Key("strlist", None, doc="instead of velocity: one expression of the time t and the "
                                                    "parameters per component [m/s]"),
    "angular_velocity": Key("vector", None, doc="angular velocity about the centre: [w] in 2D, [wx, wy, wz] in 3D "
                                                "[rad/s] (default none)"),
    "angular_velocity_expression": Key("strlist", None, doc="instead of angular_velocity: expressions of t "
                                                            "(its direction fixed in 3D) [rad/s]"),
    "friction": Key("float", 0.0, non_negative, "Coulomb friction coefficient between the surface and the "
                                                "particles (0: frictionless)"),
}
SYMMETRY_KEYS = {
    "axis": Key("int", REQUIRED, doc="the plane's normal axis (0 = x, 1 = y, 2 = z)"),
    "position": Key("float", REQUIRED, doc="the plane's coordinate on that axis [m]"),
}
INITIAL_KEYS = {
    "type": Key("str", REQUIRED, one_of("velocity", "angular_velocity", "displacement_gradient",
                                        "velocity_field", "displacement_field"),
                "what it sets, and the key that gives it: value, omega, gradient or expression"),
    "group": Key("str", "all", doc="the particles it sets"),
    "value": Key("vector", None, doc="velocity [m/s]"),
    "expression": Key("strlist", None, doc="velocity_field [m/s], displacement_field [m]: one expression "
                                           "of the reference position x, y, z and the parameters per "
                                           "component, e.g. [\"exp(-25000*(x-0.03)**2)\", \"0\"]"),
    "omega": Key("vector", None, doc="angular velocity: [w] in 2D, [wx, wy, wz] in 3D [rad/s]"),
    "gradient": Key("matrix", None, doc="displacement gradient H: u = H (X - center)"),
    "center": Key("vector", None, doc="angular_velocity, displacement_gradient: the centre (default the "
                                      "origin) [m]"),
}
PROBE_KEYS = {
    "name": Key("str", REQUIRED, doc="the name of its series in history.h5"),
    "group": Key("str", REQUIRED, doc="the particles it reduces over"),
    "quantity": Key("str", REQUIRED, probe_quantity, "the quantity it reads"),
    "component": Key("int", -1, doc="vector component, -1 for the norm / scalar quantities"),
    "reduce": Key("str", "mean", one_of("mean", "max", "min", "sum"), "how the group's values become one"),
}
CONTACT_KEYS = {
    "bodies": Key("strlist", REQUIRED, doc="the names of the two bodies that touch (parsph.contact)"),
    "radius": Key("float", 1.0, greater_than(0.5),
                  "contact radius of a particle over half its spacing: two particles touch when their "
                  "centres are closer than the mean of their spacings times this (above 0.5: at 0.5 a "
                  "particle passes untouched between two of the other body's; at most the kernel support)"),
    "stiffness": Key("float", 1.0, in_range(0.01, 1.0e4),
                     "factor on the contact stiffness of parsph.contact (Hertz's with the bodies' moduli at 1; "
                     "raise it where the pressure is a sizeable fraction of the modulus, for less overlap and a "
                     "shorter step; in [0.01, 1e4]: below, a pair gives way to a pressure of about a per cent "
                     "of the modulus, above, the contact's springs shorten the step a hundredfold)"),
    "restitution": Key("float", 1.0, in_range(0.0, 1.0),
                       "coefficient of restitution of a pair's normal impact (a dashpot; 1: none)"),
    "friction": Key("float", 0.0, non_negative, "Coulomb friction coefficient between the two bodies"),
    "self_contact": Key("bool", False, None, "bodies names one body twice: its particles that are not kernel "
                                             "neighbours touch (crack faces, folds)"),
}
GROUP_SELECTORS = ("all", "box", "sphere", "halfspace", "nearest", "extreme", "mesh_set")
GROUP_KEYS = {  # what a [groups.NAME] table's selectors take (geometry.groups.select), for the reference
    "all": Key("bool", None, doc="true: every particle"),
    "box": Key("table", None, doc="{ lower = [...], upper = [...] }: the particles in the closed box [m]"),
    "sphere": Key("table", None, doc="{ center = [...], radius = r }: the particles within r of center [m]"),
    "halfspace": Key("table", None, doc="{ point = [...], normal = [...] }: the particles with "
                                        "(X - point) . normal >= 0 [m]"),
    "nearest": Key("vector", None, doc="the one particle nearest this point (the lowest global id on ties) "
                                       "[m]"),
    "extreme": Key("table", None, doc="{ axis = k, side = \"min\" or \"max\", tolerance = t }: the particles "
                                      "within t of the smallest or largest coordinate k (t: default half the "
                                      "median particle size) [m]"),
    "mesh_set": Key("str", None, doc="the particles of a set of a mesh part's file: its elements (a Gmsh "
                                     "physical group, an Abaqus element set, KEY=VALUE of integer cell data), "
                                     "or the elements touching its nodes (an Abaqus node set, a set of faces)"),
    "mesh_part": Key("int", 0, non_negative, "with mesh_set: which of the scene's mesh parts (0: the first, "
                                             "counted over the bodies in order)"),
    "invert": Key("bool", False, doc="take the particles the selector does not"),
}
TOP_LEVEL = tuple(SECTIONS) + ("parameters", "groups", "bc", "tractions", "walls", "tools", "surfaces",
                               "symmetry", "initial", "probes", "bodies", "contact", "ties")
TIE_KEYS = ties.TIE_KEYS


def _suggest(name: str, known) -> str:
    close = difflib.get_close_matches(name, list(known), n=1, cutoff=0.6)
    return f" (did you mean '{close[0]}'?)" if close else f" (known keys: {', '.join(sorted(known))})"


def _coerce(path: str, key: Key, value: Any, dim: int | None):
    """Type-check one value; ints are accepted for floats."""
    kind = key.kind

    def bad(expected):
        return InputError(f"{path} must be {expected}, got {value!r} ({type(value).__name__})")

    if kind == "float":
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise bad("a number")
        value = float(value)
    elif kind == "int":
        if isinstance(value, bool) or not isinstance(value, int):
            raise bad("an integer")
    elif kind == "str":
        if not isinstance(value, str):
            raise bad("a string")
    elif kind == "bool":
        if not isinstance(value, bool):
            raise bad("true or false")
    elif kind == "vector":
        if not isinstance(value, list) or not all(
            isinstance(x, (int, float)) and not isinstance(x, bool) for x in value
        ):
            raise bad("a list of numbers")
        value = [float(x) for x in value]
    elif kind == "matrix":
        if not isinstance(value, list) or not all(isinstance(r, list) for r in value):
            raise bad("a list of rows")
        value = [_coerce(f"{path}[{i}]", Key("vector"), r, None) for i, r in enumerate(value)]
    elif kind == "intlist":
        if not isinstance(value, list) or not all(isinstance(x, int) and not isinstance(x, bool) for x in value):
            raise bad("a list of integers")
    elif kind == "strlist":
        if not isinstance(value, list) or not all(isinstance(x, str) for x in value):
            raise bad("a list of strings")
    if key.check is not None:
        problem = key.check(value)
        if problem:
            raise InputError(f"{path} {problem} (got {value!r})")
    return value


def _table(path: str, raw: Any, keys: dict[str, Key], dim: int | None) -> dict:
    """Validate one table against `keys`, fill defaults, reject unknown keys."""
    if not isinstance(raw, dict):
        raise InputError(f"{path} must be a table, got {type(raw).__name__}")
    out = {}
    for name in raw:
        if name not in keys:
            where = f"{path}.{name}" if path else name
            raise InputError(f"unknown key '{where}'{_suggest(name, keys)}")
    for name, key in keys.items():
        where = f"{path}.{name}" if path else name
        if raw.get(name) is not None:  # None: absent (a resolved scene's optional key)
            out[name] = raw[name] if key.kind == "table" else _coerce(where, key, raw[name], dim)
        elif key.default is REQUIRED:
            raise InputError(f"missing required key '{where}'")
        else:
            out[name] = copy.deepcopy(key.default)
    return out


def _vector_len(path: str, value, dim: int):
    if value is not None and len(value) != dim:
        raise InputError(f"{path} must have {dim} components for a {dim}D scene, got {len(value)}")


def _array(path: str, raw: Any) -> list:
    if raw is None:
        return []
    if not isinstance(raw, list) or not all(isinstance(t, dict) for t in raw):
        raise InputError(f"{path} must be an array of tables ([[{path}]])")
    return raw


def _validate_parts(raw_parts, dim: int, where: str = "geometry.parts", nested: bool = False) -> list[dict]:
    """The parts of a body, or (nested) the solids of a boolean part."""
    parts = []
    shapes = SOLIDS if nested else tuple(PART_KEYS)
    for i, raw in enumerate(_array(where, raw_parts)):
        path = f"{where}[{i}]"
        shape = raw.get("shape", None)
        if shape not in shapes:
            if shape is None:
                raise InputError(f"missing required key '{path}.shape' (one of {', '.join(shapes)})")
            raise InputError(f"{path}.shape must be one of {', '.join(shapes)}, got {shape!r}")
        if dim not in PART_DIMENSIONS[shape]:
            raise InputError(f"{path}: shape '{shape}' is not available in {dim}D")
        body = {k: v for k, v in raw.items() if k != "shape"}
        part = {"shape": shape, **_table(path, body, PART_KEYS[shape], dim)}
        for name, key in PART_KEYS[shape].items():
            if key.kind == "vector" and not (shape == "cone" and name == "axis"):
                _vector_len(f"{path}.{name}", part[name], dim)
        if shape in SOLIDS:
            if (part["spacing"] is None) != nested:
                raise InputError(f"missing required key '{path}.spacing'" if not nested else
                                 f"{path}.spacing: the parts of a boolean take its spacing; remove it")
            if nested and part["pack"]:
                raise InputError(f"{path}.pack: the boolean packs its parts together; give pack there")
            if "parts" in part:
                part["parts"] = _validate_parts(part["parts"], dim, f"{path}.parts", nested=True)
            if "vertices" in part and (part["vertices"] is None) == (part["file"] is None):
                raise InputError(f"{path}: give either vertices or file")
        if "lower" in part and any(lo >= hi for lo, hi in zip(part["lower"], part["upper"])):
            raise InputError(f"{path}: lower must be < upper in every component")
        if shape in ("ring", "polar_ring") and part["inner_radius"] >= part["outer_radius"]:
            raise InputError(f"{path}.inner_radius must be < outer_radius")
        parts.append(part)
    if not parts:
        raise InputError(f"{where} is empty: a " + ("boolean needs at least one solid" if nested else
                                                    f"body needs at least one shape ([[{where}]])"))
    return parts


def _validate_material(path: str, mat: dict) -> None:
    """The law's constants given, no constant it does not take, the law's own checks, and
    finite moduli."""
    law = LAWS[mat["model"]]
    for k in law.takes:
        if mat[k] is None:
            raise InputError(f"missing required key '{path}.{k}' for model '{law.name}'")
    allowed = law.takes + law.optional
    for k in LAW_KEYS:
        if k not in allowed and mat[k] is not None:
            takes = ", ".join(allowed[:-1]) + " and " + allowed[-1]
            raise InputError(f"{path}.{k} does not apply to model '{law.name}' (it takes {takes})")
    if law.check:
        law.check(path, mat)
    check_failure(path, mat)
    given = ", ".join(f"{k} = {mat[k]:g}" for k in ("density",) + law.takes)
    try:
        moduli = constants(mat)
        speed = moduli.wave_speed
    except (ArithmeticError, ValueError):
        moduli, speed = None, math.nan
    if moduli is None or not (all(math.isfinite(c) for c in moduli.values) and math.isfinite(moduli.youngs)
                              and math.isfinite(speed) and speed > 0.0):
        raise InputError(f"{path}: the moduli or the P-wave speed sqrt((lambda + 2 mu) / density) = {speed:g} m/s "
                         f"are not finite positive numbers in double precision ({given})")


def _validate_groups(raw: Any, dim: int, meshes: int) -> dict:
    """The [groups.NAME] tables (`meshes`: the number of mesh parts mesh_set may name)."""
    if raw is None:
        raw = {}
    if not isinstance(raw, dict):
        raise InputError("groups must be a table of named groups ([groups.NAME])")
    groups = {"all": {"all": True}}
    for name, spec in raw.items():
        path = f"groups.{name}"
        if not isinstance(spec, dict):
            raise InputError(f"{path} must be a table")
        selectors = [k for k in spec if k not in ("invert", "mesh_part")]
        for k in selectors:
            if k not in GROUP_SELECTORS:
                raise InputError(f"unknown key '{path}.{k}'{_suggest(k, GROUP_SELECTORS + ('invert', 'mesh_part'))}")
        if len(selectors) != 1:
            raise InputError(f"{path} needs exactly one of {', '.join(GROUP_SELECTORS)}")
        if "mesh_set" in spec or "mesh_part" in spec:
            if "mesh_set" not in spec:
                raise InputError(f"{path}.mesh_part goes with mesh_set")
            spec = dict(spec, **{k: _coerce(f"{path}.{k}", GROUP_KEYS[k], spec.get(k, GROUP_KEYS[k].default), dim)
                                 for k in ("mesh_set", "mesh_part")})
            if not meshes:
                raise InputError(f"{path}.mesh_set needs a part of shape 'mesh'")
            if spec["mesh_part"] >= meshes:
                raise InputError(f"{path}.mesh_part = {spec['mesh_part']}: the scene has {meshes} part(s) of "
                                 "shape 'mesh' (counted from 0)")
        groups[name] = spec
    return groups


def _validate_lists(scene: dict, raw: dict, dim: int) -> None:
    groups = scene["groups"]

    def check_group(path, name):
        if name not in groups:
            raise InputError(f"{path} names group '{name}', which is not defined{_suggest(name, groups)}")

    scene["bc"] = []
    for i, t in enumerate(_array("bc", raw.get("bc"))):
        bc = _table(f"bc[{i}]", t, BC_KEYS, dim)
        check_group(f"bc[{i}].group", bc["group"])
        if bc["components"] is None:
            bc["components"] = list(range(dim))
        if any(c < 0 or c >= dim for c in bc["components"]) or not bc["components"]:
            raise InputError(f"bc[{i}].components must be a non-empty list of integers in [0, {dim - 1}]")
        if bc["type"] == "fixed":
            if any(bc["value"] or ()) or bc["expression"] is not None:  # a resolved scene's is zero
                raise InputError(f"bc[{i}]: a 'fixed' condition takes no value")
            bc["value"] = [0.0] * dim
        else:
            _value_or_expression(f"bc[{i}]", bc, raw, dim)
        for key in ("expression", "duration"):
            if bc[key] is None:  # absent, as in scenes written before the key existed
                del bc[key]
        scene["bc"].append(bc)

    scene["tractions"] = []
    for i, t in enumerate(_array("tractions", raw.get("tractions"))):
        item = _table(f"tractions[{i}]", t, TRACTION_KEYS, dim)
        check_group(f"tractions[{i}].group", item["group"])
        _value_or_expression(f"tractions[{i}]", item, raw, dim)
        scene["tractions"].append(item)

    def obstacles(section: str, keys: dict, vectors: tuple) -> list:
        """The [[walls]] or [[tools]] tables: group checked, velocity defaulted to rest,
        vector lengths checked."""
        out = []
        for i, t in enumerate(_array(section, raw.get(section))):
            item = _table(f"{section}[{i}]", t, keys, dim)
            check_group(f"{section}[{i}].group", item["group"])
            if item["velocity"] is None:
                item["velocity"] = [0.0] * dim
            for key in vectors:
                _vector_len(f"{section}[{i}].{key}", item[key], dim)
            out.append(item)
        return out

    scene["walls"] = obstacles("walls", WALL_KEYS, ("point", "normal", "velocity", "lower", "upper"))
    for i, wall in enumerate(scene["walls"]):
        if not any(c != 0 for c in wall["normal"]):
            raise InputError(f"walls[{i}].normal must not be zero")
        if (wall["lower"] is None) != (wall["upper"] is None):
            raise InputError(f"walls[{i}]: give both lower and upper, or neither")

    scene["tools"] = obstacles("tools", TOOL_KEYS, ("lower", "upper", "velocity"))
    for i, tool in enumerate(scene["tools"]):
        smallest = min(b - a for a, b in zip(tool["lower"], tool["upper"]))
        if smallest <= 0:
            raise InputError(f"tools[{i}]: upper must exceed lower in every component")
        if tool["radius"] > 0.5 * smallest:
            raise InputError(f"tools[{i}].radius = {tool['radius']:g} exceeds half the tool's smallest "
                             f"side ({0.5 * smallest:g})")

    scene["surfaces"] = []
    for i, t in enumerate(_array("surfaces", raw.get("surfaces"))):
        path = f"surfaces[{i}]"
        item = _table(path, t, SURFACE_KEYS, dim)
        check_group(f"{path}.group", item["group"])
        if dim == 1:
            raise InputError(f"{path}: surfaces need a 2D or 3D scene")
        turn = 1 if dim == 2 else 3
        for key, size in (("translate", dim), ("center", dim), ("velocity", dim), ("velocity_expression", dim),
                          ("rotate", turn), ("angular_velocity", turn), ("angular_velocity_expression", turn)):
            if item[key] is not None and len(item[key]) != size:
                raise InputError(f"{path}.{key} must have {size} components in {dim}D, got {len(item[key])}")
        for key in ("velocity", "angular_velocity"):
            if item[key] is not None and item[f"{key}_expression"] is not None:
                raise InputError(f"{path}: give {key} or {key}_expression, not both")
            for k, text in enumerate(item[f"{key}_expression"] or ()):
                expressions.Field(f"{path}.{key}_expression[{k}]", text, raw.get("parameters", {}), 1, ("t",))
        surfaces.read(item["file"], f"{path}.file", dim)
        scene["surfaces"].append(item)

    scene["symmetry"] = [_table(f"symmetry[{i}]", t, SYMMETRY_KEYS, dim)
                         for i, t in enumerate(_array("symmetry", raw.get("symmetry")))]
    axes = [plane["axis"] for plane in scene["symmetry"]]
    for i, axis in enumerate(axes):
        if not 0 <= axis < dim:
            raise InputError(f"symmetry[{i}].axis = {axis} must be in [0, {dim - 1}]")
        if axis in axes[:i]:
            raise InputError(f"symmetry[{i}]: a second symmetry plane on axis {axis} (one per axis)")

    scene["initial"] = []
    for i, t in enumerate(_array("initial", raw.get("initial"))):
        ic = _table(f"initial[{i}]", t, INITIAL_KEYS, dim)
        check_group(f"initial[{i}].group", ic["group"])
        need = {"velocity": "value", "angular_velocity": "omega", "displacement_gradient": "gradient",
                "velocity_field": "expression", "displacement_field": "expression"}[ic["type"]]
        if ic[need] is None:
            raise InputError(f"missing required key 'initial[{i}].{need}' for type '{ic['type']}'")
        if ic["type"] == "velocity":
            _vector_len(f"initial[{i}].value", ic["value"], dim)
        if ic["type"].endswith("_field"):
            _check_expressions(f"initial[{i}]", ic["expression"], raw, dim)
        if ic["type"] == "angular_velocity":
            if dim == 1:
                raise InputError(f"initial[{i}]: angular_velocity needs a 2D or 3D scene")
            _vector_len(f"initial[{i}].omega", ic["omega"], 1 if dim == 2 else 3)
        if ic["type"] == "displacement_gradient" and (
            len(ic["gradient"]) != dim or any(len(r) != dim for r in ic["gradient"])
        ):
            raise InputError(f"initial[{i}].gradient must be a {dim}x{dim} matrix")
        if ic["center"] is None:
            ic["center"] = [0.0] * dim
        if ic["expression"] is None:  # absent, as in scenes written before the key existed
            del ic["expression"]
        _vector_len(f"initial[{i}].center", ic["center"], dim)
        scene["initial"].append(ic)

    scene["probes"] = []
    names = set()
    for i, t in enumerate(_array("probes", raw.get("probes"))):
        probe = _table(f"probes[{i}]", t, PROBE_KEYS, dim)
        check_group(f"probes[{i}].group", probe["group"])
        if not re.fullmatch(r"[A-Za-z_][A-Za-z0-9_]*", probe["name"]):
            raise InputError(f"probes[{i}].name {probe['name']!r} must be a plain name: letters, digits and "
                             "underscores, not starting with a digit (it names a series of history.h5)")
        if quantities.is_history_series(probe["name"]):
            raise InputError(f"probes[{i}].name '{probe['name']}' is the name of one of the history's own series "
                             f"({', '.join(quantities.HISTORY)}, momentum_x, wall0_force_x, ...): choose another")
        if probe["name"] in names:
            raise InputError(f"probes[{i}].name '{probe['name']}' is used twice")
        names.add(probe["name"])
        if not -1 <= probe["component"] < dim:
            raise InputError(f"probes[{i}].component must be -1 or in [0, {dim - 1}]")
        scene["probes"].append(probe)


def _power(a, b):
    """a ** b, refused before it is computed if its magnitude would exceed 2^1024."""
    if abs(a) > 1 and b > 0 and b * math.log2(abs(a)) > 1024:
        raise OverflowError("a result beyond 1.8e308 in magnitude")
    return a ** b


_OPERATORS = {
    ast.Add: operator.add, ast.Sub: operator.sub, ast.Mult: operator.mul, ast.Div: operator.truediv,
    ast.Pow: _power, ast.USub: operator.neg, ast.UAdd: operator.pos,
}


def _finite(path: str, value: Any) -> None:
    """Refuse a number that is not finite as a float: nan, inf or an integer beyond 1.8e308."""
    if isinstance(value, float) and not math.isfinite(value):
        raise InputError(f"{path} must be finite, got {value!r}")
    if isinstance(value, int) and abs(value) > sys.float_info.max:
        raise InputError(f"{path} must be finite, got a {value.bit_length()}-bit integer (beyond 1.8e308)")


def _real(value):
    """`value` if it is a real number within the float range, else ArithmeticError."""
    if isinstance(value, complex):
        raise ArithmeticError("no real value")
    if abs(value) > sys.float_info.max or not math.isfinite(value):
        raise OverflowError("a result beyond 1.8e308 in magnitude")
    return value


MAX_EXPRESSION = 300  # characters of one "= EXPR" value


def _evaluate(path: str, text: str, parameters: dict) -> float:
    """Value of an arithmetic expression over the scene's parameters (+ - * / ** and brackets).

    Every intermediate result must be a real number within the float range; powers are
    checked before they are computed and the length cap bounds the nesting, so no
    expression runs long or exhausts the parser."""
    if len(text) > MAX_EXPRESSION:
        raise InputError(f"{path}: the expression is {len(text)} characters long (at most {MAX_EXPRESSION})")

    def ev(node):
        if isinstance(node, ast.Expression):
            return ev(node.body)
        if isinstance(node, ast.Constant) and isinstance(node.value, (int, float)) and not isinstance(node.value, bool):
            return _real(node.value)
        if isinstance(node, ast.Name):
            if node.id not in parameters:
                raise InputError(f"{path}: unknown parameter '{node.id}' in '{text}'{_suggest(node.id, parameters)}")
            return parameters[node.id]
        if isinstance(node, ast.BinOp) and type(node.op) in _OPERATORS:
            return _real(_OPERATORS[type(node.op)](ev(node.left), ev(node.right)))
        if isinstance(node, ast.UnaryOp) and type(node.op) in _OPERATORS:
            return _OPERATORS[type(node.op)](ev(node.operand))
        raise InputError(f"{path}: '{text}' is not an arithmetic expression of numbers and parameters")

    try:
        value = ev(ast.parse(text, mode="eval"))
    except SyntaxError:
        raise InputError(f"{path}: '{text}' is not an arithmetic expression") from None
    except ArithmeticError as exc:
        raise InputError(f"{path}: '{text}' cannot be evaluated ({exc})") from None
    return value


def substitute_parameters(raw: dict) -> dict:
    """Replace every string value "= EXPR" by its value over the table [parameters]; refuse
    any number, given or computed, that is not finite."""
    parameters = raw.get("parameters", {})
    if not isinstance(parameters, dict):
        raise InputError("parameters must be a table of named numbers")
    for name, value in parameters.items():
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise InputError(f"parameters.{name} must be a number, got {value!r}")
        _finite(f"parameters.{name}", value)

    def walk(node, path):
        if isinstance(node, str) and node.lstrip().startswith("="):
            return _evaluate(path, node.lstrip()[1:].strip(), parameters)
        if isinstance(node, dict):
            return {k: walk(v, f"{path}.{k}" if path else k) for k, v in node.items()}
        if isinstance(node, list):
            return [walk(v, f"{path}[{i}]") for i, v in enumerate(node)]
        _finite(path, node)
        return node

    return walk(raw, "")


def upgrade(scene: dict) -> None:
    """Values of keys as scenes (and the scenes stored in checkpoints) wrote them before the
    key took its present form, in place: formulation.plastic_hourglass true / false is
    'yield_stress' / 'elastic'."""
    tables = [scene.get("formulation")] + [b.get("formulation") for b in scene.get("bodies", ())
                                           if isinstance(b, dict)]
    for form in tables:
        if isinstance(form, dict) and isinstance(form.get("plastic_hourglass"), bool):
            form["plastic_hourglass"] = "yield_stress" if form["plastic_hourglass"] else "elastic"


def _formulation(path: str, raw: Any, dim: int) -> dict:
    """A resolved formulation table: its type's defaults and rules (formulations.FORMULATIONS)."""
    form = _table(path, raw, SECTIONS["formulation"], dim)
    FORMULATIONS[form["type"]].resolve(path, form)
    return form


BODY_KEYS = {
    "name": Key("str", REQUIRED, doc="the body's name (history columns NAME.BODY)"),
    "parts": Key("table", REQUIRED, doc="array of shapes, united, as geometry.parts"),
    "material": Key("table", REQUIRED, doc="the body's material, as [material]"),
    "formulation": Key("table", {}, doc="keys of [formulation] that differ for this body"),
    "kernel": Key("table", {}, doc="keys of [kernel] that differ for this body: type, support (the bodies with "
                                   "one kernel, Hessian stabilisation and update schedule share one kernel "
                                   "relation: parsph.kernel_relation)"),
    "rigid": Key("bool", False, None, "the body moves as one rigid body and carries no stress (parsph.rigid): "
                                      "as [[bc]] holding all of it prescribe, else freely"),
}


def _validate_bodies(raw_bodies: Any, raw_formulation: Any, dim: int) -> list:
    """The [[bodies]] tables: each with its parts, material and formulation (the top-level
    [formulation] with the body's own keys over it)."""
    out, names = [], set()
    for i, raw in enumerate(_array("bodies", raw_bodies)):
        path = f"bodies[{i}]"
        body = _table(path, raw, BODY_KEYS, dim)
        if body["name"] in names or not body["name"].isidentifier():
            raise InputError(f"{path}.name must be a distinct identifier (letters, digits, _), got {body['name']!r}")
        names.add(body["name"])
        body["parts"] = _validate_parts(body["parts"], dim, f"{path}.parts")
        body["material"] = _table(f"{path}.material", body["material"], SECTIONS["material"], dim)
        _validate_material(f"{path}.material", body["material"])
        model = failure_of(body["material"])
        if body["rigid"] and (model or body["material"]["break_pairs"]):
            raise InputError(f"{path}.material.{model.key if model else 'break_pairs'}: body '{body['name']}' is rigid: "
                             "it carries no stress, so it is never damaged and does not fail or lose pairs")
        if not isinstance(body["formulation"], dict):
            raise InputError(f"{path}.formulation must be a table")
        merged = dict(raw_formulation if isinstance(raw_formulation, dict) else {}, **body["formulation"])
        body["formulation"] = _formulation(f"{path}.formulation", merged, dim)
        body["kernel"] = _table(f"{path}.kernel", body["kernel"],
                                {name: SECTIONS["kernel"][name] for name in BODY_KERNEL_KEYS}, dim)
        body["kernel"] = {name: value for name, value in body["kernel"].items() if name in raw.get("kernel", {})}
        if not body["kernel"]:  # absent, as in scenes written before the key existed
            del body["kernel"]
        if not body["rigid"]:  # absent, as in scenes written before the key existed
            del body["rigid"]
        out.append(body)
    if not out:
        raise InputError("bodies is empty: give at least one [[bodies]] table, or none and a [material]")
    _check_updated_bodies(out)
    return out


def _check_updated_bodies(bodies_: list) -> None:
    """The bodies whose reference moves (ulsph, or an Eulerian kernel) are of one kind: an
    Eulerian kernel moves its reference inside every step, ulsph between steps (each group
    of bodies on its own schedule: parsph.kernel_relation); the other bodies keep their
    initial reference beside them."""
    moving = [(i, b["formulation"]) for i, b in enumerate(bodies_) if moves(b)]
    if not moving:
        return
    first, form = moving[0]
    for i, other in moving[1:]:
        if (other.get("kernel") == "eulerian") != (form.get("kernel") == "eulerian"):
            raise InputError(f"bodies[{i}].formulation: a scene's bodies with an updated reference are all "
                             f"type = 'ulsph' or all kernel = 'eulerian' (bodies[{first}] differs)")


BODY_KERNEL_KEYS = ("type", "support")  # the keys of [kernel] a body may change


def kernel_of(scene: Scene, body) -> Any:
    """A body's kernel: the scene's [kernel] section with the body's own keys over it."""
    return dataclasses.replace(scene.kernel, **body.kernel)


def moves(body: dict) -> bool:
    """Whether a resolved body's reference moves (a rigid body carries no reference)."""
    return not body.get("rigid", False) and _kept_lists(body["formulation"])


def thickness(scene: Scene) -> float:
    """Volume per unit d-dimensional measure: the cross-section in 1D, the thickness in 2D."""
    return {1: scene.geometry.area, 2: scene.geometry.thickness, 3: 1.0}[scene.scene.dimension]


def _bodies(scene: dict) -> list:
    """The resolved scene's bodies: its [[bodies]], or the one body of geometry.parts,
    [material] and [formulation] (named "body")."""
    if "bodies" in scene:
        return scene["bodies"]
    return [{"name": "body", "parts": scene["geometry"]["parts"], "material": scene["material"],
             "formulation": scene["formulation"]}]


# The typed sections (parsph.sections) of the resolved scene, made from the Key tables:
# a section per table, an entry class per array of tables (a new array of TOP_LEVEL needs its own).
SECTION_TYPES = {name: section_type(name.capitalize(), keys) for name, keys in SECTIONS.items()}
ENTRY_TYPES = {name: section_type(cls, keys) for name, cls, keys in (
    ("bc", "Condition", BC_KEYS), ("tractions", "Traction", TRACTION_KEYS), ("walls", "Wall", WALL_KEYS),
    ("tools", "Tool", TOOL_KEYS), ("surfaces", "Surface", SURFACE_KEYS), ("symmetry", "Plane", SYMMETRY_KEYS),
    ("initial", "Initial", INITIAL_KEYS), ("probes", "Probe", PROBE_KEYS), ("contact", "ContactPair", CONTACT_KEYS),
    ("ties", "Tie", TIE_KEYS), ("bodies", "Body", BODY_KEYS))}


class _SceneBase:
    """The resolved scene, typed: a section per table (`scene.time.cfl`), a tuple of entries
    per array of tables (`scene.walls[0].normal`; `bodies`: the [[bodies]], or the one body
    of a scene without them), `parameters` and `groups` as tables of names."""

    __slots__ = ()

    def as_dict(self) -> dict:
        """The resolved scene as a nested dict, as outputs and checkpoints store it."""
        return copy.deepcopy(self._resolved)


Scene = make_dataclass("Scene", [*TOP_LEVEL, "_resolved"], bases=(_SceneBase,), frozen=True, slots=True)
Scene.__doc__, Scene.__module__ = _SceneBase.__doc__, __name__


def _typed(resolved: dict) -> Scene:
    """The Scene of a resolved scene dict."""
    values = {name: SECTION_TYPES[name].of(resolved[name]) if name in resolved else None for name in SECTIONS}
    for name, cls in ENTRY_TYPES.items():
        if name != "bodies":
            values[name] = tuple(cls.of(item) for item in resolved.get(name, ()))
    values["bodies"] = tuple(ENTRY_TYPES["bodies"].of(
        body, material=SECTION_TYPES["material"].of(body["material"]),
        formulation=SECTION_TYPES["formulation"].of(body["formulation"])) for body in _bodies(resolved))
    values["parameters"] = dict(resolved["parameters"])
    values["groups"] = copy.deepcopy(resolved["groups"])
    return Scene(**values, _resolved=copy.deepcopy(resolved))


def validate(raw: dict) -> Scene:
    """Check a raw scene dict and return the resolved scene (defaults filled in), typed.

    String values of the form "= EXPR" are first evaluated over [parameters]."""
    if not isinstance(raw, dict):
        raise InputError("a scene must be a TOML table")
    raw = substitute_parameters(raw)
    upgrade(raw)
    for name in raw:
        if name not in TOP_LEVEL:
            raise InputError(f"unknown key '{name}'{_suggest(name, TOP_LEVEL)}")
    scene_raw = raw.get("scene")
    if not isinstance(scene_raw, dict) or "dimension" not in scene_raw:
        raise InputError("missing required key 'scene.dimension'")
    scene: dict[str, Any] = {}
    dim = None
    multi = "bodies" in raw
    for section, keys in SECTIONS.items():
        if multi and section == "material":
            if "material" in raw:
                raise InputError("a scene with [[bodies]] gives each body its own [bodies.material]; "
                                 "remove the top-level [material]")
            continue
        given = raw.get(section, {})
        if multi and section == "geometry":
            if isinstance(given, dict) and given.get("parts"):  # a resolved scene's is empty
                raise InputError("a scene with [[bodies]] gives each body its own [[bodies.parts]]; "
                                 "remove geometry.parts")
            given = dict(given, parts=[]) if isinstance(given, dict) else given
        if section == "formulation":
            scene[section] = _formulation("formulation", given, dim)
            continue
        scene[section] = _table(section, given, keys, dim)
        if section == "scene":
            dim = scene["scene"]["dimension"]
    if multi:
        scene["bodies"] = _validate_bodies(raw["bodies"], raw.get("formulation", {}), dim)
    else:
        scene["geometry"]["parts"] = _validate_parts(scene["geometry"]["parts"], dim)
        _validate_material("material", scene["material"])
    for i, body in enumerate(scene.get("bodies", ())):
        if "support" in body.get("kernel", {}) and scene["kernel"]["neighbours"] > 0:
            raise InputError(f"bodies[{i}].kernel.support: kernel.neighbours = {scene['kernel']['neighbours']} "
                             "sets every particle's support from its neighbours")
    _vector_len("loads.body_acceleration", scene["loads"]["body_acceleration"], dim)
    scene["groups"] = _validate_groups(raw.get("groups"), dim,
                                       sum(p["shape"] == "mesh" for b in _bodies(scene) for p in b["parts"]))
    _validate_lists(scene, raw, dim)
    for body in _bodies(scene):
        model = failure_of(body["material"])
        if model and (LAWS[body["material"]["model"]].fluid or not FORMULATIONS[body["formulation"]["type"]].damage):
            raise InputError(f"material.{model.key}: damage is for solids computed at the particles "
                             f"(tlsph, ulsph, sph, rlm), not for model '{body['material']['model']}' with "
                             f"formulation '{body['formulation']['type']}'")
    for body in _bodies(scene):
        mat = body["material"]
        if mat["break_pairs"] and not failure_of(mat):
            raise InputError("material.break_pairs needs a failure model (material.failure_strain or jc_d1)")
        if not mat["break_pairs"]:  # absent, as in scenes written before the key existed
            del mat["break_pairs"]
    if scene["symmetry"] and any(body["formulation"]["hessian"] > 0 for body in _bodies(scene)):
        raise InputError(
            "[[symmetry]] planes cannot be used with formulation.hessian > 0: the Hessian term of "
            "[V eq. 17] (h = (l, l, l)) is not symmetric under reflection, so mirror images do not "
            "continue the body; hold the planes' normal components with [[bc]] type = 'fixed' instead")
    for b, body in enumerate(_bodies(scene)):
        FORMULATIONS[body["formulation"]["type"]].check_body(body, f"bodies[{b}]" if multi else "geometry", scene)
    if "contact" in raw:
        scene["contact"] = _validate_contact(raw["contact"], scene, dim)
    if "ties" in raw:
        entries = [_table(f"ties[{i}]", t, TIE_KEYS, dim) for i, t in enumerate(_array("ties", raw["ties"]))]
        for i, entry in enumerate(entries):
            _body_pair(f"ties[{i}]", entry["bodies"], scene)
        scene["ties"] = ties.check(entries, scene["symmetry"], _bodies(scene), moves)
    scene["parameters"] = dict(raw.get("parameters", {}))
    return _typed(scene)


def _body_pair(path: str, pair: list, scene: dict) -> None:
    """`path`.bodies (contact, ties) names two bodies of the scene."""
    names = [b["name"] for b in _bodies(scene)] if "bodies" in scene else []
    if len(pair) != 2:
        raise InputError(f"{path}.bodies must name two bodies, got {pair!r}")
    for name in pair:
        if name not in names:
            raise InputError(f"{path}.bodies names body '{name}', which is not defined"
                             f"{_suggest(name, names) if names else ' (it needs [[bodies]])'}")


def _validate_contact(raw: Any, scene: dict, dim: int) -> list:
    """The [[contact]] tables: two distinct bodies of the scene each, every pair once, one
    radius per body."""
    out, seen, radius = [], set(), {}
    for i, t in enumerate(_array("contact", raw)):
        path = f"contact[{i}]"
        item = _table(path, t, CONTACT_KEYS, dim)
        pair = item["bodies"]
        _body_pair(path, pair, scene)
        if (pair[0] == pair[1]) != item["self_contact"]:
            raise InputError(f"{path}.bodies: contact of body '{pair[0]}' with itself needs {path}.self_contact = "
                             "true" if pair[0] == pair[1] else
                             f"{path}.self_contact = true needs bodies to name one body twice, got {pair!r}")
        if frozenset(pair) in seen:
            raise InputError(f"{path}.bodies: bodies '{pair[0]}' and '{pair[1]}' are paired twice")
        seen.add(frozenset(pair))
        if item["radius"] > scene["kernel"]["support"]:
            raise InputError(f"{path}.radius = {item['radius']:g} exceeds kernel.support = "
                             f"{scene['kernel']['support']:g}: a contact radius larger than the kernel's support "
                             "would push apart particles that do not overlap")
        for name in pair:
            if radius.setdefault(name, item["radius"]) != item["radius"]:
                raise InputError(f"{path}.radius = {item['radius']:g}: body '{name}' has contact radius "
                                 f"{radius[name]:g} in an earlier [[contact]]; give it one radius")
        out.append(item)
    return out


def _kept_lists(form: dict) -> bool:
    """Whether a resolved formulation keeps its neighbour lists between reference updates."""
    return FORMULATIONS[form["type"]].moves_reference(form)


def search_every(form: dict) -> int:
    """Reference updates between neighbour searches of a resolved formulation (1: it never
    updates its reference)."""
    return form.get("search_every", 30) if _kept_lists(form) else 1


def skin(form: dict) -> float:
    """The skin of the kept neighbour lists, as a fraction of the support (0: none kept)."""
    return form.get("skin", 0.25) if _kept_lists(form) else 0.0


def _check_expressions(path: str, texts: list, raw: dict, dim: int) -> None:
    """One expression of position per component, each parsed and checked (expressions.Field)."""
    _vector_len(f"{path}.expression", texts, dim)
    for k, text in enumerate(texts):
        expressions.Field(f"{path}.expression[{k}]", text, raw.get("parameters", {}), dim)


def _value_or_expression(path: str, item: dict, raw: dict, dim: int) -> None:
    """A condition's `value` vector or its `expression` strings (checked), not both."""
    if (item["value"] is None) == (item["expression"] is None):
        raise InputError(f"{path}: give either value or expression")
    if item["expression"] is not None:
        _check_expressions(path, item["expression"], raw, dim)
    else:
        _vector_len(f"{path}.value", item["value"], dim)


def parse_override(text: str) -> tuple[list[str | int], Any]:
    """Parse a `--set key.path=value` override; the value is read as TOML, else as a string."""
    if "=" not in text:
        raise InputError(f"--set expects key.path=value, got '{text}'")
    path, value_text = text.split("=", 1)
    parts: list[str | int] = [p if not p.isdigit() else int(p) for p in path.strip().split(".")]
    if not path.strip() or any(p == "" for p in parts):
        raise InputError(f"--set: bad key path '{path}'")
    try:
        value = tomllib.loads(f"v = {value_text}")["v"]
    except ValueError:  # not TOML (TOMLDecodeError) or an integer of too many digits
        value = value_text
    except RecursionError:
        raise InputError(f"--set {path.strip()}: the value is nested too deeply") from None
    return parts, value


def apply_override(raw: dict, parts: list[str | int], value: Any) -> None:
    """Set raw[parts...] = value; arrays of tables are indexed by number (bc.0.ramp)."""
    node: Any = raw
    shown = ""
    for depth, part in enumerate(parts):
        last = depth == len(parts) - 1
        shown = f"{shown}.{part}" if shown else str(part)
        if isinstance(part, int):
            if not isinstance(node, list) or part >= len(node):
                raise InputError(f"--set {shown}: no such entry")
            if last:
                node[part] = value
            node = node[part]
        else:
            if not isinstance(node, dict):
                raise InputError(f"--set {shown}: parent is not a table")
            if last:
                node[part] = value
            else:
                node = node.setdefault(part, {})


def _read(path: str) -> dict:
    """The raw TOML table of the scene file `path`; a FIFO or device is refused unread."""
    try:
        fd = os.open(path, os.O_RDONLY | os.O_NONBLOCK)  # a FIFO without a writer must not wait
        mode = os.fstat(fd).st_mode
        if not stat.S_ISREG(mode):
            os.close(fd)
            if stat.S_ISDIR(mode):
                raise InputError(f"scene path is a directory, not a file: {path}")
            raise InputError(f"scene path is not a regular file (a pipe or a device): {path}")
        with open(fd, "rb") as fh:
            return tomllib.load(fh)
    except FileNotFoundError:
        raise InputError(f"scene file not found: {path}") from None
    except PermissionError:
        raise InputError(f"scene file is not readable: {path}") from None
    except OSError as exc:
        raise InputError(f"scene file {path} cannot be read: {exc.strerror or exc}") from None
    except ValueError as exc:  # TOMLDecodeError, UnicodeDecodeError, an integer of too many digits
        raise InputError(f"scene file {path} is not valid TOML: {exc}") from None
    except RecursionError:
        raise InputError(f"scene file {path} is not valid TOML: arrays or tables nested too deeply") from None


def _anchor_files(raw: dict, directory: str) -> None:
    """Make the relative `file` paths of the raw scene's parts (and of their boolean parts)
    and of its [[surfaces]] relative to `directory`, the scene file's."""
    def walk(parts):
        for part in parts if isinstance(parts, list) else ():
            if isinstance(part, dict):
                if isinstance(part.get("file"), str) and not os.path.isabs(part["file"]):
                    part["file"] = os.path.normpath(os.path.join(directory, part["file"]))
                walk(part.get("parts"))

    geometry = raw.get("geometry")
    walk(geometry.get("parts") if isinstance(geometry, dict) else None)
    for body in raw.get("bodies") if isinstance(raw.get("bodies"), list) else ():
        walk(body.get("parts") if isinstance(body, dict) else None)
    walk(raw.get("surfaces"))


def load(path: str, overrides: list[str] = ()) -> Scene:
    """Read a scene file, apply `--set` overrides, validate; returns the resolved scene
    (its parts' files found relative to the scene file)."""
    raw = _read(path)
    for text in overrides:
        apply_override(raw, *parse_override(text))
    _anchor_files(raw, os.path.dirname(os.path.abspath(path)))
    return validate(raw)


def to_json(scene: Scene) -> str:
    """The resolved scene as canonical JSON (stored in every output file)."""
    return json.dumps(scene._resolved, sort_keys=True)
