"""The reference of the scene keys (`parsph keys`, docs/scene-keys.md): generated from the
schema, current, complete, every key with a meaning, and new keys, shapes, selectors and
arrays of tables appearing in it without a change to the generator."""

from __future__ import annotations

import pytest

from conftest import ROOT, parsph
from parsph import config, keyref
from parsph.keys import REQUIRED, Key, in_range, non_negative, one_of, positive
from parsph.materials import FAILURES, LAWS

REGENERATE = "parsph keys --markdown > docs/scene-keys.md"


def test_docs_scene_keys_is_current():
    written = (ROOT / "docs" / "scene-keys.md").read_text()
    assert written == keyref.markdown(), f"docs/scene-keys.md is out of date: regenerate it with `{REGENERATE}`"


def test_every_key_has_a_meaning_and_every_check_says_what_it_allows():
    missing, silent = [], []
    for section in keyref.sections():
        for name, key in section.keys.items():
            r = keyref.row(name, key)
            if not r.meaning.strip():
                missing.append(f"{section.name}.{name}")
            if key.check is not None and not r.allows:
                silent.append(f"{section.name}.{name}")
    assert not missing, f"keys without a doc (give their Key a doc, then `{REGENERATE}`): {missing}"
    assert not silent, f"checks that do not describe themselves (keys.Check, or a docstring): {silent}"


def test_every_key_of_the_schema_is_in_the_reference():
    shown = {id(key) for section in keyref.sections() for key in section.keys.values()}
    tables = {name: value for name, value in vars(config).items() if name.endswith("_KEYS") and isinstance(value, dict)}
    tables.update({f"SECTIONS[{k!r}]": v for k, v in config.SECTIONS.items()})
    tables.update({f"PART_KEYS[{k!r}]": v for k, v in config.PART_KEYS.items()})
    tables.update({f"law {law.name}": law.keys for law in LAWS.values()})
    tables.update({f"failure model {m.name}": m.keys for m in FAILURES.values()})
    left_out = [f"{table}: {name}" for table, keys in tables.items() for name, key in keys.items()
                if isinstance(key, Key) and id(key) not in shown]
    assert not left_out, left_out


def test_checks_describe_themselves_with_their_messages_unchanged():
    assert (str(positive), positive(0), positive(1)) == ("> 0", "must be > 0", None)
    assert (str(non_negative), non_negative(-1e-300)) == (">= 0", "must be >= 0")
    check = in_range(0.0, 1.0, True)
    assert (str(check), check(0.0), check(1.0)) == ("in (0.0, 1.0]", "must be in (0.0, 1.0]", None)
    assert one_of("a", "b")("c") == "must be one of 'a', 'b'"
    assert keyref.row("quantity", config.PROBE_KEYS["quantity"]).allows.startswith("the name of a scalar or vector")


@pytest.mark.parametrize(("doc", "unit", "meaning"), [
    ("end time [s]", "s", "end time"),
    ("mooney_rivlin: c1 of [R eq. 18] [Pa]", "Pa", "mooney_rivlin: c1 of [R eq. 18]"),
    ("velocity [m/s] or final displacement [m]", "m/s or m", "velocity [m/s] or final displacement"),
    ("johnson_cook: c_p [J/(kg K)] (solids)", "J/(kg K)", "johnson_cook: c_p [J/(kg K)] (solids)"),
    ("omega: [w] in 2D, [wx, wy, wz] in 3D [rad/s]", "rad/s", "omega: [w] in 2D, [wx, wy, wz] in 3D"),
    ("in [0.01, 1e4]: below [V eq. 17]", "", "in [0.01, 1e4]: below [V eq. 17]"),
])
def test_units_are_read_from_the_doc(doc, unit, meaning):
    assert keyref._unit(doc) == (unit, meaning)


def test_new_keys_shapes_selectors_and_arrays_appear_unchanged_generator(monkeypatch):
    """What another branch adds to the schema (a part shape, a group selector, an array of
    tables, a key of a section) shows in the reference by itself."""
    surface = {"file": Key("str", REQUIRED, doc="an STL file"), "friction": Key("float", 0.0, non_negative, "mu")}
    monkeypatch.setattr(config, "SURFACE_KEYS", surface, raising=False)
    monkeypatch.setattr(config, "TOP_LEVEL", config.TOP_LEVEL + ("surfaces",))
    monkeypatch.setitem(config.PART_KEYS, "sphere", {"radius": Key("float", REQUIRED, positive, "radius [m]")})
    monkeypatch.setitem(config.PART_DIMENSIONS, "sphere", (3,))
    monkeypatch.setattr(config, "GROUP_SELECTORS", config.GROUP_SELECTORS + ("near_surface",))
    monkeypatch.setitem(config.SECTIONS["time"], "new_limit", Key("float", 1.0, positive, "a new limit [s]"))
    names = {s.name: s for s in keyref.sections()}
    assert names["surfaces"].title == "[[surfaces]]" and names["surfaces"].keys is surface
    assert "in 3D" in names["geometry.parts.sphere"].intro
    assert "new_limit: number [s] = 1.0; > 0" in keyref.text("time")
    assert "near_surface" in names["groups"].keys  # shown without a doc: the doc test then names it
    assert not keyref.row("near_surface", names["groups"].keys["near_surface"]).meaning


def test_a_law_section_marks_its_constants_required():
    text = keyref.text("material.johnson_cook")
    assert "jc_a: number [Pa], required; > 0" in text
    assert "jc_c: number; >= 0" in text  # optional, its default in its doc
    assert 'model = "johnson_cook"' in text


@pytest.mark.parametrize("ranks", [1, pytest.param(2, marks=pytest.mark.mpi)])
def test_keys_command(ranks):
    proc = parsph(["keys", "time"], ranks=ranks)
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout.startswith("[time]\n") and proc.stdout.count("[time]") == 1  # rank 0 prints
    assert "  end: number [s], required; > 0\n      end time\n" in proc.stdout
    walls = parsph(["keys", "walls", "--markdown"], ranks=ranks)
    assert "| `normal` | vector (one number per dimension) |" in walls.stdout
    bad = parsph(["keys", "tme"], ranks=ranks)
    assert bad.returncode == 2 and bad.stdout == "" and "Traceback" not in bad.stderr
    assert bad.stderr.count("parsph: error: no section 'tme'") == 1
    assert "did you mean 'time'" in bad.stderr and "geometry.parts.box" in bad.stderr
