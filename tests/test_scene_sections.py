"""The typed scene (config.Scene): a section per table and a tuple of entries per array of
tables, whose fields are the keys of the Key tables and whose values are the resolved
scene's; a misspelt key fails where it is read; the stored form is the resolved table, as
before, so the scenes of older outputs and checkpoints compare and load as they did."""

from __future__ import annotations

import dataclasses
import json

import pytest

from parsph import config
from parsph.sections import attribute
from physics import scene_from

# between them every table and array of tables of a scene
SCENES = ("bonded_bars", "punch_hertz_quarter", "cantilever", "funnel", "punch", "punch_stl", "bar1d")


def test_sections_are_the_key_tables_with_the_resolved_values():
    seen = set()
    for name in SCENES:
        scene = scene_from(name)
        table = scene.as_dict()
        for section, keys in config.SECTIONS.items():
            if section in table:
                typed = getattr(scene, section)
                assert [f.name for f in dataclasses.fields(typed)] == [attribute(k) for k in keys]
                assert all(typed[k] == v for k, v in table[section].items())
        for array, cls in config.ENTRY_TYPES.items():
            entries = getattr(scene, array)
            assert isinstance(entries, tuple) and all(isinstance(e, cls) for e in entries)
            if array in table:
                assert len(entries) == len(table[array])
                if entries:
                    seen.add(array)
                for entry, resolved in zip(entries, table[array]):
                    assert [f.name for f in dataclasses.fields(entry)] == [attribute(k) for k in cls.KEYS]
                    assert all(entry[k] == v for k, v in resolved.items() if k not in ("material", "formulation"))
                    for part in ("material", "formulation") if array == "bodies" else ():
                        assert all(entry[part][k] == v for k, v in resolved[part].items())
        assert len(scene.bodies) == len(table.get("bodies", [None]))
        assert scene.parameters == table["parameters"] and scene.groups == table["groups"]
    assert seen == set(config.ENTRY_TYPES)


def test_a_misspelt_key_fails_where_it_is_read():
    scene = scene_from("bonded_bars")
    with pytest.raises(AttributeError, match="cfll"):
        scene.time.cfll  # noqa: B018
    with pytest.raises(KeyError, match="its keys: type, group"):
        scene.bc[0]["rmap"]  # noqa: B018
    with pytest.raises(KeyError, match="rmap"):
        scene.bc[0].get("rmap", 0.0)
    with pytest.raises(TypeError):
        scene["time"]  # noqa: B018  the scene itself is read by attribute only
    with pytest.raises(dataclasses.FrozenInstanceError):
        scene.time.cfl = 0.9
    assert scene.bodies[0].material.lambda_ is None and scene.bodies[0].material["lambda"] is None


def test_the_stored_scene_is_the_resolved_table():
    """Keys that scenes written before them lack stay absent from the stored form (bc.duration,
    a body's kernel and rigid) and read as their defaults; a resolved scene resolves to itself."""
    scene = scene_from("bonded_bars")
    text = config.to_json(scene)
    assert text == json.dumps(scene.as_dict(), sort_keys=True)
    stored = json.loads(text)
    assert "duration" not in stored["bc"][0] and scene.bc[0].duration is None
    assert "rigid" not in stored["bodies"][0] and scene.bodies[0].rigid is False
    assert "kernel" not in stored["bodies"][0] and scene.bodies[0].kernel == {}
    again = config.validate(stored)
    assert config.to_json(again) == text and again == scene
