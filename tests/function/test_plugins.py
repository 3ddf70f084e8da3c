"""Plugins: folders, PARAMLOD_FUNCTIONS_PATH and entry points load and render; name clashes and
every validation error give a message that names the plugin, its file and the problem; the
"Writing a plugin" guide's example runs."""
import re
import sys
from pathlib import Path

import numpy as np
import pytest
import sympy as sp

import paramlod as pl
from paramlod.function import plugins, registry
from paramlod import Part

HERE = Path(__file__).resolve().parent
PLUGINS = HERE / "plugins"
THIS_FILE = str(Path(__file__).resolve())


@pytest.fixture(autouse=True)
def clean_registry(monkeypatch):
    monkeypatch.delenv(registry.ENV_VAR, raising=False)
    registry.refresh()
    yield
    registry.refresh()


def render_covers(fn_or_name, eye=(0, 2.5, 3.5), params=None):
    scene = pl.Scene()
    scene.add(fn_or_name, params=params)
    frame = pl.render(scene, pl.Camera.look_at(eye, (0, 0, 0), size=(64, 64)))
    return frame.coverage.mean()


# --- discovery --------------------------------------------------------------------------------
def test_a_plugin_folder_loads_lists_and_renders():
    found = registry.add_plugin_path(PLUGINS / "folder_good")
    assert sorted(f.name for f in found) == ["signpost", "snippet_bowl", "wavy_disc"]
    rows = {r["name"]: r for r in registry.describe_functions()}
    disc = rows["wavy_disc"]
    assert disc["origin"] == f"plugin folder {PLUGINS / 'folder_good'}"
    assert disc["source"].startswith(str(PLUGINS / "folder_good" / "wavy_disc.py"))
    assert {"name": "amps", "default": [0.05, 0.03, 0.02], "size": 3} in disc["params"]
    assert {"name": "t", "default": 0.0, "size": 1} in disc["params"]   # the implicit time
    assert rows["snippet_bowl"]["kind"] == "snippet" and "sphere" in rows   # built-ins stay
    assert render_covers("wavy_disc") > 0.1
    assert render_covers("snippet_bowl") > 0.1


def test_the_environment_variable_adds_folders(monkeypatch):
    monkeypatch.setenv(registry.ENV_VAR, f"{PLUGINS / 'folder_good'}:{HERE / 'no_such_folder'}")
    with pytest.raises(pl.FunctionError, match="no_such_folder does not exist"):
        registry.get_function("wavy_disc")
    monkeypatch.setenv(registry.ENV_VAR, str(PLUGINS / "folder_good"))
    assert registry.get_function("wavy_disc").origin.startswith("plugin folder")
    # parts may name functions of the same folder; they follow the parent's time
    post = registry.get_function("signpost")
    parts = post.expand_parts({"t": 1.0})
    assert [p.function.name for p in parts] == ["cone", "wavy_disc"]
    assert parts[1].params == {"radius": 0.3, "t": 1.0}
    top = post.evaluate(1.0, 0.0, t=1.0)
    np.testing.assert_allclose(parts[1].transform[:3, 3], top + 0.05 * parts[1].transform[:3, 2], atol=1e-9)


def test_an_entry_point_plugin_loads_and_renders(monkeypatch):
    monkeypatch.syspath_prepend(str(PLUGINS / "ep_site"))
    fn = registry.get_function("ep_barrel")
    assert fn.origin == "entry point 'test_shapes = paramlod_test_shapes' of paramlod-test-shapes 0.1"
    assert render_covers("ep_barrel") > 0.1


def test_two_plugins_with_one_name_are_an_error_naming_both():
    with pytest.raises(pl.FunctionError) as err:
        registry.add_plugin_path(PLUGINS / "folder_clash")
    msg = str(err.value)
    assert "two functions are named 'sphere'" in msg
    assert "built-in" in msg and "functions/sphere.py" in msg
    assert str(PLUGINS / "folder_clash" / "sphere.py") in msg
    assert registry.get_function("sphere").origin == "built-in"   # the failed folder is not kept


def test_a_snippet_that_does_not_compile_fails_when_its_folder_loads():
    with pytest.raises(pl.FunctionError) as err:
        registry.add_plugin_path(PLUGINS / "folder_broken_snippet")
    msg = str(err.value)
    assert "plugin 'broken_snippet'" in msg and str(PLUGINS / "folder_broken_snippet" / "broken.py") in msg
    assert "does not compile" in msg and "undefined_offset" in msg
    assert re.search(r">\s*\d+ \|\s+return p \+ undefined_offset;", msg)   # the generated line, marked


def test_an_unknown_helper_is_named_with_its_line():
    with pytest.raises(pl.FunctionError) as err:
        registry.add_plugin_path(PLUGINS / "folder_unknown_helper")
    msg = str(err.value)
    assert f"plugin 'lumpy' ({PLUGINS / 'folder_unknown_helper' / 'uses_unknown.py'}" in msg
    assert "unknown name 'smoothstep' at line 8" in msg and "from paramlod.dsl import smoothstep" in msg


# --- validation at definition time ---------------------------------------------------------------
def expect_error(match, define):
    """``define()`` must raise a FunctionError naming its plugin and this file, matching ``match``."""
    with pytest.raises(pl.FunctionError) as err:
        define()
    msg = str(err.value)
    assert THIS_FILE in msg, msg
    assert re.search(match, msg), msg
    return msg


def test_wrong_signatures():
    def no_v():
        @pl.parametric()
        def only_u(u):
            return u, u, u
    msg = expect_error(r"wrong signature \(u\): it must start with the two surface parameters", no_v)
    assert "plugin 'only_u'" in msg

    def star_args():
        @pl.parametric()
        def varargs(u, v, *rest):
            return u, v, 0
    expect_error(r"plugin 'varargs'.*\*args/\*\*kwargs \(rest\) are not allowed", star_args)


def test_a_parameter_without_default_and_an_unused_default():
    def missing():
        @pl.parametric(params={"a": 1.0})
        def needs_b(u, v, a, b):
            return u, v, a * b
    expect_error(r"plugin 'needs_b'.*parameter\(s\) b have no default", missing)

    def unused():
        @pl.parametric(params={"a": 1.0, "zz": 2.0})
        def extra(u, v, a):
            return u, v, a
    expect_error(r"plugin 'extra'.*params zz are not arguments", unused)


def test_return_values_that_are_not_three_expressions():
    def two():
        @pl.parametric()
        def flat(u, v):
            return u, v
    expect_error(r"plugin 'flat'.* must return three expressions \(x, y, z\), got 2 values", two)

    def vector_component():
        @pl.parametric()
        def nested(u, v):
            return u, v, (u, v)
    expect_error(r"plugin 'nested'.*component z is not a", vector_component)

    def stray_symbol():
        @pl.parametric()
        def uses_w(u, v):
            return u, v, sp.Symbol("w")
    expect_error(r"plugin 'uses_w'.*component z uses unknown symbol\(s\) \['w'\]", stray_symbol)

    def string_u():   # said "unknown symbol(s) ['u']; use only u, v", which read as a contradiction
        @pl.parametric()
        def uses_text(u, v):
            return "u", v, sp.Symbol("v") * 0 + 1
    expect_error(r"plugin 'uses_text'.*component x uses unknown symbol\(s\) \['u'\].*u: a string or a sympy "
                 r"Symbol made in the plugin", string_u)

    def division_by_zero():
        @pl.parametric()
        def infinite(u, v):
            return u, v, sp.Integer(1) / 0
    expect_error(r"plugin 'infinite'.*component z is infinite or undefined", division_by_zero)

    def complex_value():   # failed only when the OpenCL code was compiled
        @pl.parametric()
        def imaginary(u, v):
            return u + sp.sqrt(-2), v, u
    expect_error(r"plugin 'imaginary'.*component x is complex \(it holds the imaginary unit I", complex_value)


def test_a_plugin_file_that_exits_is_an_error(tmp_path):
    """A plugin whose top level calls sys.exit ended paramlod silently with its exit code."""
    (tmp_path / "quits.py").write_text("import sys\nsys.exit(3)\n")
    with pytest.raises(pl.FunctionError, match=r"plugin file .*quits.py called sys.exit\(3\) while being imported"):
        plugins.load_plugin_file(tmp_path / "quits.py")


def test_empty_and_reversed_domains():
    def empty():
        @pl.parametric(u=(1, 1))
        def flat(u, v):
            return u, v, 0
    expect_error(r"plugin 'flat'.*the u domain \(1.0, 1.0\) is empty", empty)

    def reversed_():
        @pl.parametric(v=(sp.pi, 0))
        def backwards(u, v):
            return u, v, 0
    expect_error(r"plugin 'backwards'.*the v domain \(3.14\d*, 0.0\) is reversed", reversed_)


def test_an_unknown_helper_in_a_body():
    def body():
        @pl.parametric()
        def misspelt(u, v):
            return u, v, smothstep(0, 1, u)  # noqa: F821 - the mistake under test
    expect_error(r"plugin 'misspelt'.*unknown name 'smothstep' at line \d+.*did you mean smoothstep", body)


def test_a_python_if_on_an_expression_suggests_where():
    def body():
        @pl.parametric()
        def branchy(u, v):
            return u, v, (u if u < 0.5 else 1 - u)
    expect_error(r"plugin 'branchy'.*use paramlod.dsl.where\(cond, a, b\)", body)


def test_a_function_no_backend_has():
    from paramlod.function.plugins import validate

    @pl.parametric()
    def bessel(u, v):
        return u, v, sp.besselj(0, u)
    with pytest.raises(pl.FunctionError, match=r"plugin 'bessel' \(.*test_plugins.py:\d+\): uses besselj, "
                                               r"which has no equivalent in the generated GPU code"):
        validate([bessel], compile=False)


def test_snippet_rules():
    def double_literal():
        @pl.parametric(snippet="float h = 0.5;\nreturn VEC3(u, v, h);")
        def halfway(u, v):
            return u, v, 0.5 + 0 * u
    expect_error(r"plugin 'halfway'.*snippet line 1: the float literal '0.5' needs an f suffix", double_literal)

    def c_cast():
        @pl.parametric(snippet="int k = 2;\nreturn VEC3(u, v, (float)k);")
        def casting(u, v):
            return u, v, 2 + 0 * u
    expect_error(r"plugin 'casting'.*snippet line 2: write conversions as FLOAT\(x\)", c_cast)

    def one_sided_builtin():
        @pl.parametric(snippet="return VEC3(u, v, fabs(u - 0.5f));")
        def folded(u, v):
            return u, v, abs(u - 0.5)
    expect_error(r"plugin 'folded'.*snippet line 1: 'fabs' exists in only one of .* use the dialect's ABS",
                 one_sided_builtin)

    def no_return():
        @pl.parametric(snippet="VEC3(u, v, 0.0f);")
        def silent(u, v):
            return u, v, 0 * u
    expect_error(r"plugin 'silent'.*never returns", no_return)

    def reserved_name():
        @pl.parametric(params={"length": 1.0}, snippet="return VEC3(u, v, 0.0f);")
        def named(u, v, length):
            return u, v, 0 * u
    expect_error(r"plugin 'named'.*parameter 'length' cannot be used in a snippet", reserved_name)

    def bad_reference():
        @pl.parametric(snippet="return VEC3(u, v, 0.0f);")
        def two_arrays(u, v):
            return u, v
    expect_error(r"plugin 'two_arrays'.*numpy reference must return three arrays", bad_reference)


def test_part_errors():
    def outside():
        @pl.parametric(parts=[Part("cone", at=(2.0, 0.0))])
        def holder(u, v):
            return u, v, 0
    expect_error(r"plugin 'holder'.*parts\[0\] \(cone\): at = \(2.0, 0.0\) lies outside", outside)

    def bad_params():
        @pl.parametric(parts=[Part(registry.get_function("cone"), at=(0.5, 0.5), params={"hight": 1})])
        def typo(u, v):
            return u, v, 0
    expect_error(r"plugin 'typo'.*parts\[0\] \(cone\).*no parameter 'hight'", bad_params)

    @pl.parametric(parts=[Part("sphere", at=(0.5, 0.5), params={"radiuz": 1})])   # resolved when placed
    def typo_by_name(u, v):
        return u, v, 0
    with pytest.raises(pl.FunctionError, match=r"plugin 'typo_by_name'.*part typo_by_name/sphere\[0\]: function "
                                               r"'sphere' has no parameter 'radiuz'"):
        typo_by_name.expand_parts()

    @pl.parametric(parts=[Part("sphere", at=(0.0, 0.0))])
    def tip(u, v):
        return u * sp.cos(v), u * sp.sin(v), 1 - u   # a cone: the frame at its tip is undefined
    with pytest.raises(pl.FunctionError, match=r"plugin 'tip'.*part tip/sphere\[0\] sits at \(u, v\) = "
                                               r"\(0.0, 0.0\), where the surface frame is undefined"):
        tip.expand_parts()


# --- the guide ------------------------------------------------------------------------------------
def test_the_writing_plugins_guide_runs(tmp_path, monkeypatch):
    """docs/writing-plugins.md: the plugin file is written where it says, then every other Python
    block runs in order (they load the folder, render, and build a composite object)."""
    text = (HERE.parents[1] / "docs" / "writing-plugins.md").read_text()
    blocks = re.findall(r"```python\n(.*?)```", text, re.S)
    assert len(blocks) >= 3
    monkeypatch.chdir(tmp_path)
    namespace: dict = {}
    for code in blocks:
        first = code.splitlines()[0]
        if first.startswith("# file: "):
            path = tmp_path / first[len("# file: "):].strip()
            path.parent.mkdir(parents=True, exist_ok=True)
            path.write_text(code)
        else:
            exec(compile(code, "writing-plugins.md", "exec"), namespace)
    frame = namespace["frame"]
    assert frame.coverage.mean() > 0.05
    assert (tmp_path / "twisted_ring.png").is_file()
    ring = registry.get_function("twisted_ring")
    assert [p.name for p in ring.params] == ["t", "radius", "tube", "twist", "squash"]
    # the animated ring changes with t
    assert not np.allclose(ring.evaluate(1.0, 0.5, t=0.0), ring.evaluate(1.0, 0.5, t=1.0))
    sys.modules.pop("twisted_ring", None)
