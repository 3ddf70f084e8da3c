"""What the viewer shows, loaded through the same loaders as ``paramlod render`` (scene files:
paramlod.app.scenefile via paramlod.app.dist.prepare_scene; plugin files:
paramlod.function.plugins; function names: the registry), and the files it watches.

Watching is mtime polling (portable, no extra dependency): ``Watcher.changed()`` compares each
watched file's (mtime, size) with what it saw last; the viewer polls it a few times a second, so a
save is picked up well within a second. A source that no longer loads keeps its last good
``Loaded`` and reports the message the CLI would print (``cli_message``)."""
from __future__ import annotations

import os
import tomllib
from dataclasses import dataclass, field
from pathlib import Path

from paramlod.app import dist
from paramlod.app.scenefile import FILE_OBJECT_NAMES, file_object_kind
from paramlod.errors import FunctionError, ParamlodError
from paramlod.function import registry
from paramlod.function.define import ParametricFunction
from paramlod.function.plugins import load_plugin_file, validate
from paramlod.pipeline.plan import check_variant
from paramlod.pipeline.settings import RenderSettings
from paramlod.scene.framing import framing_camera, scene_box
from paramlod.scene.scene import Scene

POLL_SECONDS = 0.2
DEFAULT_SIZE = (1280, 720)


def cli_message(exc: BaseException) -> str:
    """The line ``paramlod`` prints for ``exc`` (paramlod.app.args.run_reporting_errors)."""
    if isinstance(exc, RecursionError):
        return ("paramlod: error: an expression is nested too deeply to handle (Python's recursion limit); "
                "name intermediate results with let(...)")
    return f"paramlod: error: {exc}"


@dataclass
class Loaded:
    """A loaded source: what to draw, the start camera and what to watch."""
    scene: Scene
    camera: object
    settings: RenderSettings
    variant: str
    label: str
    watched: list = field(default_factory=list)
    up: tuple = (0.0, 1.0, 0.0)
    functions: list = field(default_factory=list)   # a plugin file's functions (N cycles them)
    box: tuple | None = None
    animation: dict | None = None                   # a scene file's [animation]: t0, t1 (the viewer loops it)


def _plugin_files(functions) -> list[Path]:
    """Source files of plugin functions (built-ins and entry points are not watched)."""
    out = []
    for f in functions:
        if (f.origin or "").startswith("plugin folder") and f.source and Path(f.source).is_file():
            out.append(Path(f.source).resolve())
    return out


class Source:
    """``spec``: a scene file (.toml), a plugin file (.py), a mesh file (OBJ, PLY, STL, OFF, glTF,
    GIfTI, .meshlod), a .surfels file or a registered function's name.
    ``load()`` (re)loads it; plugin folders of the registry are loaded again when one of their
    files changed, so a scene naming a plugin function sees the edit."""

    def __init__(self, spec: str, size=None, variant: str | None = None, aa: str | None = None):
        self.spec, self.size, self.variant, self.aa = str(spec), size, variant, aa
        check_variant(variant)   # at start, as `paramlod render --variant` refuses it
        path = Path(self.spec)
        suffix, alone = path.suffix.lower(), file_object_kind(path)
        # a mesh or surfel file loads as a scene of that one object (paramlod.app.scenefile)
        self.kind = "scene" if suffix == ".toml" or alone else "plugin" if suffix == ".py" else "function"
        if self.kind != "function" and not path.is_file():
            what = "plugin file" if self.kind == "plugin" else FILE_OBJECT_NAMES.get(alone, "scene file")
            raise ParamlodError(f"{what} {path} does not exist" if not path.exists() else f"{what} {path} is not a file")
        self.path = path.resolve() if self.kind != "function" else None
        self.function_index = 0
        self.plugin_folders = list(registry.plugin_paths())   # given with --functions / the environment

    @classmethod
    def of_scene(cls, scene: Scene, camera, settings: RenderSettings | None = None, variant: str | None = None,
                 label: str = "scene") -> "Source":
        """A Scene made in Python (pl.show, the bench): nothing to watch, the same loop."""
        src = cls.__new__(cls)
        src.spec, src.size, src.variant, src.aa = label, tuple(camera.size), variant, None
        src.kind, src.path, src.function_index, src.plugin_folders = "object", None, 0, []
        src._fixed = Loaded(scene, camera, settings or RenderSettings(), variant or "points", label)
        return src

    def _reload_folders(self) -> None:
        registry.refresh()
        for folder in self.plugin_folders:
            registry.add_plugin_path(folder)

    def load(self, folders_changed: bool = False) -> Loaded:
        """Load the source now; raises the loaders' ParamlodError (the CLI's message) when it fails."""
        if folders_changed and self.plugin_folders:
            self._reload_folders()
        if self.kind == "object":
            return self._fixed
        if self.kind == "scene":
            return self._scene()
        if self.kind == "plugin":
            funcs = load_plugin_file(self.path)
            if not funcs:
                raise FunctionError(f"plugin file {self.path}: defines no public @parametric function")
            validate(funcs)
            fn = funcs[self.function_index % len(funcs)]
            loaded = self._one_function(fn, f"{fn.name} ({self.path.name}"
                                            + (f", {self.function_index % len(funcs) + 1}/{len(funcs)})" if len(funcs) > 1 else ")"))
            loaded.functions = funcs
            loaded.watched = [self.path]
            return loaded
        fn = registry.get_function(self.spec)
        loaded = self._one_function(fn, fn.name)
        loaded.watched = _plugin_files([fn])
        return loaded

    def _scene(self) -> Loaded:
        sf, variant = dist.prepare_scene(self.path, self.size, self.variant, self.aa, cache=False)
        up = (0.0, 1.0, 0.0)
        if not file_object_kind(self.path):
            try:
                up = tuple(float(x) for x in tomllib.loads(self.path.read_text(encoding="utf-8"))
                           .get("camera", {}).get("up", [0.0, 1.0, 0.0]))
            except (OSError, tomllib.TOMLDecodeError, TypeError, ValueError):
                pass   # load_scene has checked the field; this only reads it back
        return Loaded(sf.scene, sf.camera, sf.settings, variant, self.path.name,
                      [self.path, *_plugin_files(sf.scene.functions())], up, animation=sf.animation)

    def _one_function(self, fn: ParametricFunction, label: str) -> Loaded:
        scene = Scene()
        scene.add(fn)
        settings = RenderSettings()
        variant = self.variant or "points"
        if self.aa:
            settings.apply_aa(self.aa, points_only=variant == "points", variant=variant)
        camera = framing_camera(scene, size=tuple(self.size or DEFAULT_SIZE))
        return Loaded(scene, camera, settings, variant, label, [], box=scene_box(scene))


class Watcher:
    """Polls the (mtime, size) of files; a file that vanished or appeared counts as changed."""

    def __init__(self, paths=()):
        self.seen: dict[Path, tuple | None] = {}
        self.watch(paths)

    @staticmethod
    def _stamp(path: Path):
        try:
            st = os.stat(path)
        except OSError:
            return None
        return st.st_mtime_ns, st.st_size

    def watch(self, paths) -> None:
        """Watch exactly ``paths`` from now on, their present state taken as seen."""
        self.seen = {Path(p): self._stamp(Path(p)) for p in paths}

    def changed(self) -> list[Path]:
        """The watched files whose state differs from what was seen last (each reported once)."""
        out = []
        for p, old in self.seen.items():
            now = self._stamp(p)
            if now != old:
                self.seen[p] = now
                out.append(p)
        return out
