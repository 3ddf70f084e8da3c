"""Scene files are data: a gallery scene with any field replaced by a value of another kind, or
removed, loads or fails with one SceneError (a ParamlodError naming the field), never another
exception, and never by allocating without bound (a curtain of 10^12 loops was killed for memory)."""
import copy
import json
import math
import tomllib
from pathlib import Path

import pytest
from hypothesis import given, settings, strategies as st

import paramlod as pl
from paramlod.app.scenefile import load_scene

GALLERY = Path(__file__).resolve().parents[2] / "gallery"
# not the fibre curtain (358k loops) and the 19,600-glyph field: each load takes seconds; csa_small64d
# has the field's keys
SCENES = sorted(p for p in GALLERY.glob("*.toml") if p.stem not in ("fiber_curtain", "hardi_field"))
ODD = [0, -1, 1e30, -1e30, math.nan, math.inf, "", "x", [], [1], [1, 2], [1, 2, 3, 4], [[1]], {}, {"a": 1}, True,
       2 ** 63 - 1, 1e-30, [math.nan] * 3, ["a", "b", "c"], "../../etc/passwd", "nope.ply", [1e30] * 3, 10 ** 9]


def toml_value(v) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, float) and not math.isfinite(v):
        return "nan" if math.isnan(v) else ("inf" if v > 0 else "-inf")
    if isinstance(v, (int, float)):
        return repr(v)
    if isinstance(v, str):
        return json.dumps(v)
    if isinstance(v, list):
        return "[" + ", ".join(toml_value(x) for x in v) + "]"
    return "{" + ", ".join(f"{json.dumps(k)} = {toml_value(x)}" for k, x in v.items()) + "}"


def toml_text(doc: dict) -> str:
    """``doc`` as TOML: top-level values, then tables, then arrays of tables."""
    def tables_list(v):
        return isinstance(v, list) and v and all(isinstance(x, dict) for x in v)
    lines = [f"{json.dumps(k)} = {toml_value(v)}" for k, v in doc.items() if not isinstance(v, dict) and not tables_list(v)]
    for k, v in doc.items():
        for table, header in ([(v, f"[{json.dumps(k)}]")] if isinstance(v, dict) else
                              [(x, f"[[{json.dumps(k)}]]") for x in v] if tables_list(v) else []):
            lines += [header, *(f"{json.dumps(kk)} = {toml_value(vv)}" for kk, vv in table.items())]
    return "\n".join(lines) + "\n"


def places(node, at=()):
    """Every key path in ``node``: its tables' fields and the tables of its arrays of tables (not the
    items of a list of numbers, which would make most of the changes)."""
    items = (node.items() if isinstance(node, dict) else
             enumerate(node) if isinstance(node, list) and all(isinstance(x, dict) for x in node) else ())
    for k, v in items:
        yield at + (k,)
        yield from places(v, at + (k,))


def changed(doc: dict, changes) -> dict:
    """``doc`` with each (place index, value) of ``changes`` applied; value None removes the place."""
    doc = copy.deepcopy(doc)
    for pick, value in changes:
        at = list(places(doc))
        if not at:
            break
        path = at[pick % len(at)]
        parent = doc
        for k in path[:-1]:
            parent = parent[k]
        if value is None:
            del parent[path[-1]]
        else:
            parent[path[-1]] = copy.deepcopy(value)   # not shared: a later change may go inside it
    return doc


def loads_or_names_its_error(doc: dict, tag: str) -> None:
    text = toml_text(doc)
    try:
        tomllib.loads(text)
    except tomllib.TOMLDecodeError:   # a change TOML cannot write (a table inside an array of values)
        return
    p = GALLERY / f"_mutated_{tag}.toml"   # beside the data files the scene names
    p.write_text(text)
    try:
        load_scene(p, size=(32, 24))
    except pl.ParamlodError:
        pass
    finally:
        p.unlink()


@pytest.mark.parametrize("scene", SCENES, ids=[p.stem for p in SCENES])
def test_every_field_of_another_kind_or_removed(scene):
    """Each place of each scene, once removed and once as a list, a string, a negative number and a
    table of its own (an [animation] that was a list raised TypeError)."""
    doc = tomllib.loads(scene.read_text())
    for k in range(len(list(places(doc)))):
        for value in (None, [1, 2], "x", -1, {"a": 1}):
            loads_or_names_its_error(changed(doc, [(k, value)]), scene.stem)


@settings(max_examples=60, deadline=None)
@given(st.sampled_from(SCENES), st.lists(st.tuples(st.integers(0, 10 ** 6), st.sampled_from([None, *ODD])),
                                         min_size=2, max_size=3))
def test_several_odd_changes_at_once(scene, changes):
    loads_or_names_its_error(changed(tomllib.loads(scene.read_text()), changes), scene.stem)


def test_the_writer_round_trips_every_gallery_scene():
    for scene in SCENES:
        doc = tomllib.loads(scene.read_text())
        assert tomllib.loads(toml_text(doc)) == doc, scene.name


@pytest.fixture(autouse=True)
def _no_leftovers():
    yield
    assert not list(GALLERY.glob("_mutated_*.toml"))
