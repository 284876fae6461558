"""The package order of the project (STYLE: imports go one way), checked on the source with ``ast``.

``ORDER`` lists the packages bottom to top. A module may import its own package and any package listed
below it, never one listed above it, at module level or inside a function. A module belongs to the
longest listed prefix of its name (``pipeline.schema.ptpb`` to ``pipeline.schema``, ``pipeline.runner``
to ``pipeline``). Why the order is as it is:

- ``common``: the leaves below everything (atomic writes, units, peak memory, logging set-up, paths);
  they import no project module.
- ``render._core``: the compiled C++ core, which imports nothing of ours.
- ``pipeline.schema``: the config's schema. It reads the render settings that the core declares, so a
  setting is declared once, and every package that takes a config section sits above it.
- ``geometry``: the growth model. It takes its config section from the schema and knows nothing of
  light: it imports nothing under ``render``, not even the compiled core (a rule of its own below,
  since ``render._core`` sits lower in the order).
- ``render.engine``: the Embree ray engine and the loader of the scene folder, which the scene builder,
  the denoiser's guides, our renderer and the Mitsuba export share; it reads meshes with geometry.
- ``render.scene``: the neutral scene built from the geometry, timed with the ray engine.
- ``render.output``: what reads the files that renderers write (formats, figures, videos, metrics,
  the denoiser and its guides, reports); it knows the scene's model but no renderer.
- ``render.ptpb`` and ``render.mitsuba``: our renderer and the reference, which write through
  render.output's file formats and know nothing of each other.
- ``render.lidar``: laser shots, rendered by ``render.ptpb`` into scenes made of ``render.scene``'s
  shapes and optics, reported with ``render.output``'s pages.
- ``pipeline``: the roof (the runner, the stage list, the CLI, the sweeps), which imports every stage.

The reference renderers' libraries (Mitsuba 3, mitransient, Dr.Jit) are imported only by
``render.mitsuba`` and ``pipeline``. Scripts on top (benchmarks/, examples/, render/core/tests/) are no
packages and import freely. ``EXCEPTIONS`` may name at most three upward imports, each with its reason.
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
ORDER = (
    "common",
    "render._core",
    "pipeline.schema",
    "geometry",
    "render.engine",
    "render.scene",
    "render.output",
    "render.ptpb",
    "render.mitsuba",
    "render.lidar",
    "pipeline",
)
TOP_LEVEL = ("common", "geometry", "render", "pipeline")
# A parent package that only holds listed packages; its __init__ imports nothing.
CONTAINERS = ("render",)
# Folders of scripts inside the packages' tree; like benchmarks/ and examples/, they are run, not imported.
SCRIPT_FOLDERS = ("render/core/tests",)
RENDERER_LIBRARIES = ("mitsuba", "mitransient", "drjit")
RENDERER_LIBRARY_USERS = ("render.mitsuba", "pipeline")
# Imports the order would allow but the project keeps apart: importer package -> imported prefix, reason.
KEPT_APART = {"geometry": ("render", "geometry never imports render")}
# (importing module, imported module) -> why the upward import is allowed; at most three.
EXCEPTIONS: dict[tuple[str, str], str] = {}


def imported_modules(source: str, module: str, is_package: bool = False) -> list[tuple[int, str]]:
    """(line, absolute module name) of every import in ``source``, the module ``module`` importing (a package's
    ``__init__`` with ``is_package``); ``importlib.import_module("name")`` with a literal name counts too."""
    found = []
    package = module if is_package else module.rsplit(".", 1)[0]
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, ast.Import):
            found += [(node.lineno, alias.name) for alias in node.names]
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                parent = package.split(".")[: len(package.split(".")) - node.level + 1]
                base = ".".join(parent + ([base] if base else []))
            # ``from render import _core`` imports the module render._core.
            found += [(node.lineno, f"{base}.{alias.name}") for alias in node.names] or [(node.lineno, base)]
        elif isinstance(node, ast.Call) and node.args and isinstance(node.args[0], ast.Constant):
            called = node.func.attr if isinstance(node.func, ast.Attribute) else getattr(node.func, "id", "")
            if called == "import_module" and isinstance(node.args[0].value, str):
                found.append((node.lineno, node.args[0].value))
    return found


def _under(name: str, prefix: str) -> bool:
    return name == prefix or name.startswith(prefix + ".")


def package_of(name: str) -> str | None:
    """The listed package a module belongs to: the longest listed prefix of its name (None: none is)."""
    matches = [package for package in ORDER if _under(name, package)]
    return max(matches, key=len) if matches else None


def violations(module: str, source: str, is_package: bool = False) -> list[str]:
    """The forbidden imports of one module, as 'module:line imports name (rule)'."""
    own = package_of(module)
    if own is None:
        return [f"{module} belongs to no package of the order"]
    out = []
    for line, name in imported_modules(source, module, is_package):
        if (module, name) in EXCEPTIONS:
            continue
        where = f"{module}:{line} imports {name}"
        if name.split(".")[0] in RENDERER_LIBRARIES:
            if own not in RENDERER_LIBRARY_USERS:
                out.append(f"{where} (only {' and '.join(RENDERER_LIBRARY_USERS)} import the reference renderers)")
            continue
        if name.split(".")[0] not in TOP_LEVEL:
            continue
        target = package_of(name)
        if target is None:
            out.append(f"{where} (it belongs to no package of the order)")
        elif own in KEPT_APART and _under(name, KEPT_APART[own][0]):
            out.append(f"{where} ({KEPT_APART[own][1]})")
        elif ORDER.index(target) > ORDER.index(own):
            out.append(f"{where} ({target} sits above {own} in the package order)")
    return out


def project_modules() -> list[tuple[str, Path]]:
    """(module name, file) of every Python file of the packages, scripts left out."""
    modules = []
    for package in TOP_LEVEL:
        for path in sorted((ROOT / package).rglob("*.py")):
            relative = path.relative_to(ROOT)
            if any(relative.is_relative_to(folder) for folder in SCRIPT_FOLDERS):
                continue
            parts = relative.with_suffix("").parts
            modules.append((".".join(parts[:-1] if parts[-1] == "__init__" else parts), path))
    return modules


def test_the_project_keeps_the_package_order():
    found = []
    for name, path in project_modules():
        if name not in CONTAINERS:
            found += violations(name, path.read_text(encoding="utf-8"), path.name == "__init__.py")
    assert not found, "imports that run up the package order:\n" + "\n".join(found)


def test_every_module_belongs_to_a_listed_package():
    modules = project_modules()
    unlisted = [name for name, _ in modules if name not in CONTAINERS and package_of(name) is None]
    assert not unlisted, f"modules of no package in ORDER (list their package there): {unlisted}"
    for name, path in modules:
        if name in CONTAINERS:
            assert not imported_modules(path.read_text(encoding="utf-8"), name, True), f"{path} imports something"
    names = {name for name, _ in modules}
    empty = [p for p in ORDER if p != "render._core" and not any(_under(name, p) for name in names)]
    assert not empty, f"packages in ORDER without a module: {empty}"
    assert (ROOT / "render" / "_core.pyi").is_file()


def test_the_exceptions_are_few_named_and_still_needed():
    assert len(EXCEPTIONS) <= 3
    sources = {name: (path.read_text(encoding="utf-8"), path.name == "__init__.py") for name, path in project_modules()}
    for (module, name), reason in EXCEPTIONS.items():
        assert reason.strip(), f"{module} -> {name} needs its reason"
        assert name in {n for _, n in imported_modules(sources[module][0], module, sources[module][1])}, (
            f"{module} no longer imports {name}: remove the exception"
        )


@pytest.mark.parametrize(
    ("name", "package"),
    [
        ("common.atomic", "common"),
        ("pipeline.schema.ptpb", "pipeline.schema"),
        ("pipeline.runner", "pipeline"),
        ("render.engine", "render.engine"),
        ("render.output.guides", "render.output"),
        ("render._core", "render._core"),
        ("render", None),
        ("render.extras", None),
        ("numpy", None),
    ],
)
def test_a_module_belongs_to_the_longest_listed_prefix(name, package):
    assert package_of(name) == package


@pytest.mark.parametrize(
    ("module", "source", "rule"),
    [
        ("geometry.mesh", "from render.scene import shapes\n", "geometry never imports render"),
        ("geometry.stage", "from pipeline.runner import run_dir\n", "pipeline sits above geometry"),
        ("geometry.mesh", "from render import _core\n", "geometry never imports render"),
        ("common.atomic", "from pipeline.schema import Config\n", "pipeline.schema sits above common"),
        ("pipeline.schema.ptpb", "from geometry.mesh import heightfield_solid\n", "geometry sits above"),
        ("render.engine", "def f():\n    from render.ptpb.api import render\n", "render.ptpb sits above render.engine"),
        ("render.scene.build", "def f():\n    from render.output.figures import x\n", "render.output sits above"),
        ("render.output.summary", "def f():\n    from render.lidar.table import x\n", "render.lidar sits above"),
        ("render.output.compare", "from .. import ptpb\n", "render.ptpb sits above render.output"),
        ("render.ptpb.stage", "from pipeline.runner import checkpoint_dir\n", "pipeline sits above render.ptpb"),
        ("render.scene.build", "from pipeline import stages\n", "pipeline sits above render.scene"),
        ("render.scene.build", "from render.extras import x\n", "no package of the order"),
        ("render.output.figures", "import mitsuba as mi\n", "reference renderers"),
        ("render.lidar.stage", "import mitransient\n", "reference renderers"),
        ("render.scene.build", "import importlib\nimportlib.import_module('drjit')\n", "reference renderers"),
    ],
)
def test_a_forbidden_edge_is_caught(module, source, rule):
    found = violations(module, source)
    assert len(found) == 1 and rule in found[0], found


@pytest.mark.parametrize(
    ("module", "source"),
    [
        ("render.ptpb.stage", "from common.atomic import write_json_atomic\nfrom pipeline.schema.ptpb import X\n"),
        ("render.output.compare", "from render.output.files import RenderOutputs\nfrom . import metrics\n"),
        ("render.output.guides", "def f():\n    from render.engine import RayEngine\n"),
        ("render.scene.build", "from geometry.meshio import read_mesh\nfrom render.engine import RayEngine\n"),
        ("pipeline.schema.ptpb", "from render import _core\n"),
        ("render.lidar.table", "from render.output.report import html_page\n"),
        ("render.mitsuba.export", "import mitsuba as mi\nimport importlib\nimportlib.import_module('mitransient')\n"),
        ("pipeline.stages", "from render.ptpb.stage import run_render_stage\nfrom render.lidar.table import x\n"),
    ],
)
def test_allowed_edges_pass(module, source):
    assert violations(module, source) == []


def test_a_package_init_imports_relative_to_itself():
    source = "from .api import render\n"
    assert imported_modules(source, "render.ptpb", is_package=True) == [(1, "render.ptpb.api.render")]
    assert imported_modules(source, "render.ptpb.stage") == [(1, "render.ptpb.api.render")]
    assert imported_modules(source, "render.ptpb") == [(1, "render.api.render")]


# Test folders that are not packages themselves: what each one tests.
TEST_FOLDERS_BESIDE_PACKAGES = {
    "render/engine": "the module render/engine.py",
    "pipeline/cluster": "pipeline's sweeps and shards on a real SLURM cluster (make cluster-test)",
}


def test_tests_mirror_the_packages():
    """Every folder of tests names the package it tests (tests/render/ptpb tests render/ptpb), so a reader finds a
    module's tests where the module is."""
    tests = ROOT / "tests"
    folders = {p.parent.relative_to(tests).as_posix() for p in tests.rglob("test_*.py")} - {"."}
    strays = sorted(
        f for f in folders if f not in TEST_FOLDERS_BESIDE_PACKAGES and not (ROOT / f / "__init__.py").is_file()
    )
    assert not strays, f"test folders that name no package: {strays}"
    assert {"geometry", "render/ptpb", "render/output", "common"} <= folders
