"""The import rule of the project (STYLE: imports go one way), checked on the source with ``ast``.

- ``geometry`` never imports ``render``.
- Domain code (``geometry``, ``render``) imports from ``pipeline`` only its leaf modules: the config
  schema, atomic writes, paths, units, memory measurement and logging set-up; never the runner, the stage list, the CLI, the
  config loader or the sweep driver.
- ``render.output`` imports no renderer: neither our core's Python face nor the Mitsuba adapter.
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PIPELINE_LEAVES = (
    "pipeline.schema",
    "pipeline.atomic",
    "pipeline.paths",
    "pipeline.units",
    "pipeline.memory",
    "pipeline.log",
)
RENDERERS = ("render.ptpb", "render.mitsuba", "render._core", "mitsuba", "mitransient", "drjit")


def imported_modules(source: str, module: str) -> list[tuple[int, str]]:
    """(line, absolute module name) of every import in ``source``, the module ``module`` importing."""
    found = []
    package = module.rsplit(".", 1)[0]
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
    return found


def _under(name: str, prefixes: tuple[str, ...]) -> bool:
    return any(name == p or name.startswith(p + ".") for p in prefixes)


def violations(module: str, source: str) -> list[str]:
    """The forbidden edges of one module, as 'module:line imports name (rule)'."""
    out = []
    for line, name in imported_modules(source, module):
        if _under(module, ("geometry",)) and _under(name, ("render",)):
            out.append(f"{module}:{line} imports {name} (geometry never imports render)")
        if _under(module, ("geometry", "render")) and _under(name, ("pipeline",)):
            if not any(name == leaf or name.startswith(leaf + ".") for leaf in PIPELINE_LEAVES):
                out.append(f"{module}:{line} imports {name} (domain code imports only pipeline's leaf modules)")
        if _under(module, ("render.output",)) and _under(name, RENDERERS):
            out.append(f"{module}:{line} imports {name} (render.output imports no renderer)")
    return out


def project_modules() -> list[tuple[str, Path]]:
    modules = []
    for package in ("geometry", "render", "pipeline"):
        for path in sorted((ROOT / package).rglob("*.py")):
            parts = path.relative_to(ROOT).with_suffix("").parts
            name = ".".join(parts[:-1] if parts[-1] == "__init__" else parts)
            modules.append((name, path))
    return modules


def test_the_project_keeps_the_import_rule():
    found = [v for name, path in project_modules() for v in violations(name, path.read_text(encoding="utf-8"))]
    assert not found, "forbidden imports:\n" + "\n".join(found)


def test_the_walk_sees_every_package():
    names = {name for name, _ in project_modules()}
    assert {"geometry.stage", "render.output.compare", "render.ptpb.stage", "pipeline.runner"} <= names


@pytest.mark.parametrize(
    ("module", "source", "rule"),
    [
        ("geometry.mesh", "from render.scene import shapes\n", "geometry never imports render"),
        ("geometry.mesh", "import render.ptpb\n", "geometry never imports render"),
        ("render.ptpb.stage", "from pipeline.runner import checkpoint_dir\n", "leaf modules"),
        ("render.scene.build", "from pipeline import stages\n", "leaf modules"),
        ("render.output.compare", "from render.ptpb.api import render\n", "no renderer"),
        ("render.output.report", "from .. import _core\n", "no renderer"),
        ("render.output.figures", "import mitsuba as mi\n", "no renderer"),
    ],
)
def test_a_forbidden_edge_is_caught(module, source, rule):
    found = violations(module, source)
    assert len(found) == 1 and rule in found[0], found


@pytest.mark.parametrize(
    ("module", "source"),
    [
        ("render.ptpb.stage", "from pipeline.atomic import write_json_atomic\nfrom pipeline.schema.ptpb import X\n"),
        ("render.output.compare", "from render.output.files import RenderOutputs\nfrom . import metrics\n"),
        ("pipeline.stages", "from render.ptpb.stage import run_render_stage\n"),
        ("render.scene.build", "from geometry.meshio import read_mesh\n"),
    ],
)
def test_allowed_edges_pass(module, source):
    assert violations(module, source) == []
