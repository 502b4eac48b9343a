"""What the package's sources depend on, read from the sources alone: the find_package calls of its CMake files and
the third-party imports of its Python files, each with where it is and the kinds of dependency it makes (code the
package runs needs an exec dependency, the build outside its tests a build dependency). tools/check_rosdep.py
checks them against package.xml.

No rosdep here, and nothing outside the standard library.
"""

from __future__ import annotations

import ast
import importlib.util
import re
import sys
import sysconfig
from pathlib import Path
from typing import NamedTuple

ALL_KINDS = ("build", "build_export", "exec", "test")  # the kinds of dependency package.xml declares

PYTHON_TREES = ("src/grid_puzzle_localization", "scripts", "tools", "bench", "test")
RUNTIME_TREES = ("src", "scripts")  # what the package runs: its imports need exec keys


class Dependency(NamedTuple):
    """One dependency the sources take: ``name`` (the find_package name or the top-level module), ``what`` (e.g.
    ``import numpy``) at ``where`` (file:line), satisfied by a dependency of one of ``kinds``."""

    name: str
    what: str
    where: str
    kinds: tuple[str, ...]


CMAKE_TOKEN = re.compile(r'#[^\n]*|"(?:\\.|[^"\\])*"|[()]|[^\s()#"]+')  # comment, string, parenthesis, word


def cmake_commands(path: Path) -> list[tuple[str, list[str], int]]:
    """The commands of a CMake file: (name in lower case, arguments without quotes or parentheses, line)."""
    text = path.read_text()
    commands: list[tuple[str, list[str], int]] = []
    depth = 0
    for match in CMAKE_TOKEN.finditer(text):
        token = match.group()
        if token in "()":
            depth += 1 if token == "(" else -1
        elif depth == 0 and not token.startswith("#"):
            commands.append((token.lower(), [], text.count("\n", 0, match.start()) + 1))
        elif not token.startswith("#"):
            commands[-1][1].append(token.strip('"'))
    return commands


def find_packages(root: Path) -> list[Dependency]:
    """The packages the find_package calls of the CMake files find. In the package's CMakeLists.txt they are build
    dependencies, except under if(CATKIN_ENABLE_TESTING), where a test dependency does too, as in the CMake projects
    of test/ (sanitizers, fuzzing)."""
    found = []
    for path in [root / "CMakeLists.txt", *sorted((root / "test").rglob("CMakeLists.txt"))]:
        testing = [path.parent != root]  # one entry per open if(): whether it is a test-only block
        for command, args, line in cmake_commands(path):
            if command == "if":
                testing.append(testing[-1] or "CATKIN_ENABLE_TESTING" in args)
            elif command in ("else", "elseif"):
                testing[-1] = testing[-2]
            elif command == "endif":
                testing.pop()
            elif command == "find_package" and args:
                kinds = ("build", "test") if testing[-1] else ("build",)
                where = f"{path.relative_to(root)}:{line}"
                for name in find_package_names(args):
                    found.append(Dependency(name, f"find_package({name})", where, kinds))
    return found


def find_package_names(args: list[str]) -> list[str]:
    """The packages one find_package call finds: its first argument, and for catkin its COMPONENTS."""
    if args[0] != "catkin" or "COMPONENTS" not in args:
        return [args[0]]
    components = args[args.index("COMPONENTS") + 1 :]
    return [args[0], *(c for c in components if not c.isupper())]


def python_files(root: Path) -> list[Path]:
    """The package's Python files: *.py in its Python trees and the Python scripts of scripts/."""
    files = [p for tree in PYTHON_TREES for p in sorted((root / tree).rglob("*.py")) if "__pycache__" not in p.parts]
    scripts = sorted(p for p in (root / "scripts").iterdir() if p.is_file() and p.suffix != ".py")
    return files + [p for p in scripts if "python" in p.read_text(errors="replace").partition("\n")[0]]


def own_modules(files: list[Path], root: Path) -> set[str]:
    """Module names the package itself provides: every Python file's and every directory's name in its trees."""
    names = {p.stem for p in files}
    names.update(part for p in files for part in p.relative_to(root).parent.parts)
    return names


def imported_modules(path: Path) -> list[tuple[str, int]]:
    """The top-level modules a Python file imports (absolute imports), with their lines."""
    modules = []
    for node in ast.walk(ast.parse(path.read_bytes(), filename=str(path))):
        if isinstance(node, ast.Import):
            modules += [(alias.name.split(".")[0], node.lineno) for alias in node.names]
        elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
            modules.append((node.module.split(".")[0], node.lineno))
    return modules


def is_stdlib(name: str) -> bool:
    """Whether a top-level module is part of Python's standard library. Before Python 3.10 (no
    sys.stdlib_module_names): a built-in module, or one found in the standard library's directory (not in its
    site-packages)."""
    names = getattr(sys, "stdlib_module_names", None)
    if names is not None:
        return name in names
    if name in sys.builtin_module_names:
        return True
    spec = importlib.util.find_spec(name)
    if spec is None or spec.origin is None:
        return False
    if spec.origin == "frozen":
        return True
    origin = Path(spec.origin).resolve()
    stdlib = {Path(sysconfig.get_paths()[k]).resolve() for k in ("stdlib", "platstdlib")}
    installed = {"site-packages", "dist-packages"} & set(origin.parts)
    return not installed and any(d in origin.parents for d in stdlib)


def third_party_imports(root: Path, ignored: frozenset[str] = frozenset()) -> list[Dependency]:
    """The imports of the package's Python files that neither the package itself nor the standard library provides,
    nor name a module of ``ignored``."""
    files = python_files(root)
    own = own_modules(files, root)
    found = []
    for path in files:
        rel = path.relative_to(root)
        kinds = ("exec",) if rel.parts[0] in RUNTIME_TREES else ALL_KINDS
        for module, line in imported_modules(path):
            if module in own or module in ignored or is_stdlib(module):
                continue
            found.append(Dependency(module, f"import {module}", f"{rel}:{line}", kinds))
    return found
