"""The reference of every scene key, generated from the schema: parsph.config's tables,
the part shapes, the material laws' and failure models' keys and the formulation families'.
`parsph keys [SECTION]` prints it as text, `parsph keys --markdown` as docs/scene-keys.md.

The walk is generic: a section of config.SECTIONS, a shape of config.PART_KEYS, a law of
materials.LAWS, a selector of config.GROUP_SELECTORS, or an array of tables of
config.TOP_LEVEL whose keys config declares as NAME_KEYS (bc: BC_KEYS, walls: WALL_KEYS,
bodies: BODY_KEYS) appears here as it is declared. A key's unit is the bracketed unit in
its doc ("[m/s]"); its allowed values are what its check says of itself (keys.describe).
"""

from __future__ import annotations

import difflib
import json
import re
import textwrap
from dataclasses import dataclass

from parsph import config
from parsph.errors import InputError
from parsph.keys import REQUIRED, Key, describe
from parsph.materials import FAILURES, LAWS

KINDS = {"int": "integer", "float": "number", "str": "string", "bool": "boolean",
         "vector": "vector (one number per dimension)", "matrix": "matrix (list of rows)",
         "intlist": "list of integers", "strlist": "list of strings", "table": "table",
         "value": "number or list (see the meaning)"}
UNIT_SYMBOLS = {"1", "m", "s", "kg", "N", "Pa", "J", "W", "K", "rad"}
PARAMETER = Key("float", REQUIRED, doc="a named number: any string value \"= EXPR\" in the scene is evaluated over "
                                       "the parameters (numbers, + - * / ** and brackets), so that --set "
                                       "parameters.NAME=VALUE re-scales the scene")


@dataclass
class Section:
    """A table of the scene as the reference shows it."""

    name: str  # what `parsph keys NAME` takes: "time", "bc", "geometry.parts.box", "material.johnson_cook"
    title: str  # how the scene file writes it
    keys: dict  # {name: Key}
    intro: str = ""
    required: tuple = ()  # keys required here though their Key is not (a law's constants)


@dataclass
class Row:
    """One key as the reference prints it."""

    name: str
    kind: str
    unit: str
    default: str  # "required", "" (none) or the TOML value
    allows: str
    meaning: str


def _unit(doc: str) -> tuple[str, str]:
    """(unit, meaning) of a key's doc: the bracketed units it names ("[m/s]"; several
    joined by "or"), and the doc without a unit that ends it."""
    units = [u for u in re.findall(r"\[([^\[\]]+)\]", doc)
             if re.fullmatch(r"[\w/^() .*-]+", u) and set(re.findall(r"[A-Za-z]+|^1(?=/)", u)) <= UNIT_SYMBOLS
             and re.search(r"[A-Za-z]", u)]
    meaning = doc
    if units and doc.rstrip().endswith(f"[{units[-1]}]"):
        meaning = doc.rstrip()[:-len(units[-1]) - 2].rstrip(" ;,")
    return " or ".join(dict.fromkeys(units)), meaning


def row(name: str, key: Key, required: bool = False) -> Row:
    """The reference's row of one key."""
    unit, meaning = _unit(key.doc)
    if required or key.default is REQUIRED:
        default = "required"
    elif key.default is None:
        default = ""
    else:
        default = json.dumps(key.default, ensure_ascii=False)
    return Row(name, KINDS.get(key.kind, key.kind), unit, default, describe(key.check), meaning)


def _array_tables() -> dict:
    """config's arrays of tables ([[bc]], [[walls]], [[bodies]], ...) and their keys: for an
    array NAME of config.TOP_LEVEL, config's table NAME_KEYS, or that of the singular
    (WALL_KEYS for walls, BODY_KEYS for bodies)."""
    tables = {name[:-5].lower(): value for name, value in vars(config).items()
              if name.endswith("_KEYS") and isinstance(value, dict) and value
              and all(isinstance(k, Key) for k in value.values())}
    out = {}
    for array in config.TOP_LEVEL:
        if array in config.SECTIONS:
            continue
        stems = (array, array[:-1], array[:-3] + "y") if array.endswith("ies") else (array, array[:-1])
        found = next((tables[s] for s in stems if s in tables), None)
        if found is not None:
            out[array] = found
    return out


def _parts() -> list:
    out = []
    for shape, keys in config.PART_KEYS.items():
        dims = config.PART_DIMENSIONS.get(shape, ())
        where = ", ".join(f"{d}D" for d in dims)
        out.append(Section(f"geometry.parts.{shape}", f'[[geometry.parts]] shape = "{shape}"', keys,
                           f"a part of a body, in {where} (also in [[bodies.parts]])" if where else
                           "a part of a body (also in [[bodies.parts]])"))
    return out


def _materials() -> list:
    out = []
    for law in LAWS.values():
        intro = f"the constants of material model '{law.name}'" + (f" ({law.doc})" if law.doc else "")
        out.append(Section(f"material.{law.name}", f'[material] model = "{law.name}"', law.keys, intro,
                           law.takes))
    for model in FAILURES.values():
        out.append(Section(f"material.failure.{model.name}", f"[material] {model.key} = ...", model.keys,
                           f"failure model '{model.name}' over the material's law, enabled by {model.key}"))
    return out


def _groups() -> Section:
    names = dict.fromkeys([*config.GROUP_SELECTORS, *config.GROUP_KEYS])
    keys = {name: config.GROUP_KEYS.get(name, Key("table")) for name in names}
    return Section("groups", "[groups.NAME]", keys,
                   "a named set of particles, selected by exactly one key below (and invert) in the "
                   "reference configuration; the group 'all' needs no table")


def sections() -> list:
    """Every section of the reference, in the order of config.TOP_LEVEL, each followed by
    the ones under it (geometry's part shapes, material's laws and failure models)."""
    arrays = _array_tables()
    by_law = {k for law in LAWS.values() for k in law.keys} | {k for m in FAILURES.values() for k in m.keys}
    out = []
    for name in config.TOP_LEVEL:
        if name in config.SECTIONS:
            keys = config.SECTIONS[name]
            if name == "material":  # the laws' and failure models' keys: under material.MODEL
                keys = {k: key for k, key in keys.items() if k not in by_law}
            out.append(Section(name, f"[{name}]", keys))
            out.extend({"geometry": _parts, "material": _materials}.get(name, list)())
        elif name == "parameters":
            out.append(Section(name, "[parameters]", {"NAME": PARAMETER}))
        elif name == "groups":
            out.append(_groups())
        elif name in arrays:
            out.append(Section(name, f"[[{name}]]", arrays[name], "an array of tables"))
    return out


def select(name: str | None) -> list:
    """The sections `name` names, with those under it ("material": also material.MODEL);
    all for None. InputError naming the known sections for an unknown name."""
    every = sections()
    if name is None:
        return every
    chosen = [s for s in every if s.name == name or s.name.startswith(name + ".")]
    if not chosen:
        close = difflib.get_close_matches(name, [s.name for s in every], n=1)
        raise InputError(f"no section '{name}' of the scene keys" + (f" (did you mean '{close[0]}'?)" if close else "")
                         + f"; the sections are: {', '.join(s.name for s in every)}")
    return chosen


def _rows(section: Section) -> list:
    return [row(name, key, name in section.required) for name, key in section.keys.items()]


def text(name: str | None = None, width: int = 92) -> str:
    """The reference of section `name` (and those under it; None: all) as plain text."""
    blocks = []
    for section in select(name):
        lines = [f"{section.title}" + (f"  ({section.name})" if section.name != section.title.strip("[]") else "")]
        if section.intro:
            lines += textwrap.wrap(section.intro, width, initial_indent="  ", subsequent_indent="  ",
                                   break_on_hyphens=False)
        for r in _rows(section):
            head = f"  {r.name}: {r.kind}" + (f" [{r.unit}]" if r.unit else "")
            head += {"required": ", required", "": ""}.get(r.default, f" = {r.default}")
            head += f"; {r.allows}" if r.allows else ""
            lines.append(head)
            lines += textwrap.wrap(r.meaning, width, initial_indent="      ", subsequent_indent="      ",
                                  break_on_hyphens=False)
        blocks.append("\n".join(lines))
    return "\n\n".join(blocks) + "\n"


def _cell(value: str) -> str:
    """Text as a Markdown table cell shows it as written."""
    return value.replace("|", "\\|").replace("*", "\\*").replace("<", "&lt;").replace("\n", " ")


def markdown(name: str | None = None) -> str:
    """The reference of section `name` (and those under it) as Markdown; None: all of it,
    with a heading (docs/scene-keys.md)."""
    out = [] if name else [
        "# Scene keys", "",
        "Every key a scene file takes, generated from the schema by `parsph keys --markdown` (do not edit "
        "by hand; `parsph keys SECTION` prints one section). A vector has one number per dimension of the "
        "scene, units are SI, `required` keys have no default, and a key without a default is left out "
        "unless given. Any string value `\"= EXPR\"` is evaluated over `[parameters]`.", ""]
    for section in select(name):
        out += [f"## `{section.title}`", "",
                f"`parsph keys {section.name}`" + (f": {section.intro}" if section.intro else ""), "",
                "| key | type | unit | default | allowed | meaning |", "|---|---|---|---|---|---|"]
        for r in _rows(section):
            default = r.default if r.default in ("required", "") else f"`{r.default}`"
            out.append(f"| `{r.name}` | {r.kind} | {_cell(r.unit)} | {_cell(default)} | {_cell(r.allows)} | "
                       f"{_cell(r.meaning)} |")
        out.append("")
    return "\n".join(out)
