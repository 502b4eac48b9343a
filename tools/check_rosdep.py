#!/usr/bin/env python3
"""Checks package.xml against rosdep and against what the package uses, offline.

Every key of package.xml is resolved with rosdep against the rosdistro copy in ../shared/rosdistro: all keys for
Ubuntu 20.04 with ROS Noetic (where the ROS package keys resolve to ros-noetic-*), the system keys (every key that
is not a ROS package) for Debian 12 and Debian 11 too (Debian names its ROS packages itself, which rosdistro does
not list). Then every find_package of the CMake files and every import of a third-party Python module of
src/grid_puzzle_localization, scripts, tools, bench and test must be covered by a key of a kind that fits: code
that the package runs (src/, scripts/) needs an exec key, the build outside its tests a build key.

    check_rosdep.py                              # check; print the keys and their packages
    check_rosdep.py --apt-names debian:bullseye  # the apt packages of the system keys, one a line
    check_rosdep.py --ros-keys                   # the keys that are ROS packages, one a line

Needs rosdep's Python package (Debian: python3-rosdep2, which `make setup` installs; elsewhere pip's rosdep).
Exit status: 0 when everything resolves and is covered, 1 when not (each problem on stderr), 2 on bad usage.
"""

from __future__ import annotations

import argparse
import ast
import hashlib
import importlib.util
import os
import re
import sys
import sysconfig
import xml.etree.ElementTree as ET
from pathlib import Path
from typing import NamedTuple

ROOT = Path(__file__).resolve().parents[1]
ROSDISTRO = "noetic"
ROSDISTRO_FILES = ("index-v4.yaml", "noetic/distribution.yaml", "rosdep/base.yaml", "rosdep/python.yaml")
ROS_OS = "ubuntu:focal"  # the platform rosdistro noetic releases for: every key must resolve there
SYSTEM_OSES = ("debian:bookworm", "debian:bullseye")  # only the system keys resolve there

# package.xml dependency tags and the kinds of dependency each declares
TAG_KINDS = {
    "buildtool_depend": ("build",),
    "build_depend": ("build",),
    "build_export_depend": ("build_export",),
    "buildtool_export_depend": ("build_export",),
    "exec_depend": ("exec",),
    "depend": ("build", "build_export", "exec"),
    "test_depend": ("test",),
}
ALL_KINDS = ("build", "build_export", "exec", "test")

# find_package names of system libraries and the rosdep keys that provide them. A ROS package (pluginlib, rostest,
# catkin's COMPONENTS) is covered by the key of its own name. An empty tuple: part of the toolchain, no key needed.
FIND_PACKAGE_KEYS = {
    "Ceres": ("libceres-dev",),
    "CURL": ("libcurl-dev",),
    "Eigen3": ("eigen",),
    "GTest": ("gtest", "libgtest-dev"),
    "nlohmann_json": ("nlohmann-json-dev",),
    "OpenMP": ("libgomp1", "libomp-dev"),  # GCC's libgomp; LLVM's libomp with clang
    "OpenSSL": ("libssl-dev",),
    "PCL": ("libpcl-all-dev",),
    "Threads": (),  # the C library's pthreads
}
# Third-party Python modules and the rosdep keys that install them. A ROS package's module (rospy, genpy,
# sensor_msgs, ...) is covered by the key of its own name.
MODULE_KEYS = {
    "catkin_pkg": ("python3-catkin-pkg",),
    "hypothesis": ("python3-hypothesis",),
    "matplotlib": ("python3-matplotlib",),
    "numpy": ("python3-numpy",),
    "psutil": ("python3-psutil",),
    "pytest": ("python3-pytest",),
    "rospkg": ("python3-rospkg",),
    "scipy": ("python3-scipy",),
    "tqdm": ("python3-tqdm",),
    "urllib3": ("python3-urllib3",),
    "yaml": ("python3-yaml",),
}
# Modules that rosdep cannot install (no key, not in Debian or Ubuntu): allowed only from a pip requirements file,
# module -> its PyPI distribution.
PIP_ONLY_MODULES = {"atheris": "atheris", "embreex": "embreex", "lzf": "python-lzf"}
# pip requirements files and the kinds of use they serve: requirements.txt is the user's (features of the nodes and
# of `gpm`), tools/requirements-dev.txt the developers' (lint, fuzzing).
REQUIREMENT_FILES = {"requirements.txt": ("exec",), "tools/requirements-dev.txt": ("build", "test")}
# Modules that neither package.xml nor a requirements file installs, and why.
UNDECLARED_MODULES = {
    "evo": "test_evaluation's cross-check, skipped by pytest.importorskip without it",
    "rosdep2": "rosdep itself (this tool), which installs the keys; its test skips without it",
}

PYTHON_TREES = ("src/grid_puzzle_localization", "scripts", "tools", "bench", "test")
RUNTIME_TREES = ("src", "scripts")  # what the package runs: its imports need exec keys


class Use(NamedTuple):
    """A dependency the sources take: ``what`` (e.g. ``import numpy``) at ``where`` (file:line), acceptable when
    package.xml has one of ``keys`` with one of ``kinds``."""

    what: str
    where: str
    keys: tuple[str, ...]
    kinds: tuple[str, ...]


class Resolution(NamedTuple):
    """What rosdep made of one key for one OS: ``installer`` (apt, pip, ...) and ``packages``, or ``error``."""

    installer: str
    packages: tuple[str, ...]
    error: str


def parse_args(argv: list[str] | None) -> argparse.Namespace:
    """The command line."""
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--package-xml", type=Path, default=ROOT / "package.xml", help="default: the package's")
    parser.add_argument(
        "--rosdistro-dir", type=Path, default=ROOT.parent / "shared" / "rosdistro", help="default: ../shared/rosdistro"
    )
    parser.add_argument(
        "--work-dir", type=Path, default=ROOT / "build" / "rosdep", help="rosdep's sources list and cache"
    )
    query = parser.add_mutually_exclusive_group()
    query.add_argument(
        "--apt-names", metavar="OS:CODENAME", help="only print the apt packages of the system keys for this OS"
    )
    query.add_argument("--ros-keys", action="store_true", help="only print the keys that are ROS packages")
    parser.add_argument(
        "--kinds", default=",".join(ALL_KINDS), help="of the keys these two print (default: %(default)s)"
    )
    args = parser.parse_args(argv)
    args.kinds = tuple(args.kinds.split(","))
    if not set(args.kinds) <= set(ALL_KINDS):
        parser.error(f"--kinds takes {','.join(ALL_KINDS)}")
    if args.apt_names and args.apt_names.count(":") != 1:
        parser.error("--apt-names takes OS:CODENAME, e.g. debian:bullseye")
    return args


def package_keys(package_xml: Path) -> dict[str, set[str]]:
    """The rosdep keys of a package.xml and the kinds each is declared with."""
    keys: dict[str, set[str]] = {}
    for element in ET.parse(package_xml).getroot():
        for kind in TAG_KINDS.get(element.tag, ()):
            keys.setdefault((element.text or "").strip(), set()).add(kind)
    return keys


def prepare_rosdep(rosdistro_dir: Path, work_dir: Path) -> None:
    """Points rosdep at the rosdistro copy (environment variables, a sources list in ``work_dir``) and updates its
    cache there when the copy changed since the last update."""
    rosdistro_dir = rosdistro_dir.resolve()
    sources = work_dir / "sources"
    os.environ.update(
        ROSDEP_SOURCE_PATH=str(sources),
        ROSDISTRO_INDEX_URL=(rosdistro_dir / "index-v4.yaml").as_uri(),
        ROS_HOME=str(work_dir / "home"),
        ROS_DISTRO=ROSDISTRO,
    )
    digest = hashlib.sha256(str(rosdistro_dir).encode())
    for name in ROSDISTRO_FILES:
        digest.update((rosdistro_dir / name).read_bytes())
    stamp = work_dir / "rosdistro.sha256"
    if stamp.is_file() and stamp.read_text() == digest.hexdigest():
        return
    sources.mkdir(parents=True, exist_ok=True)
    lines = (f"yaml {(rosdistro_dir / 'rosdep' / name).as_uri()}\n" for name in ("base.yaml", "python.yaml"))
    (sources / "20-default.list").write_text("".join(lines))
    from rosdep2.sources_list import update_sources_list

    update_sources_list(ros_distro=ROSDISTRO, quiet=True)
    stamp.write_text(digest.hexdigest())


def rosdep_view(os_spec: str):
    """rosdep's view of all keys for ``os_spec`` (``name:codename``) and the installer context to resolve them."""
    from rosdep2 import create_default_installer_context
    from rosdep2.lookup import RosdepLookup
    from rosdep2.rospkg_loader import DEFAULT_VIEW_KEY
    from rosdep2.sources_list import SourcesListLoader

    os_override = tuple(os_spec.split(":"))
    loader = SourcesListLoader.create_default(os_override=os_override)
    view = RosdepLookup.create_from_rospkg(sources_loader=loader).get_rosdep_view(DEFAULT_VIEW_KEY)
    context = create_default_installer_context()
    context.set_os_override(*os_override)
    return view, context


def ros_package_keys(view) -> set[str]:
    """The keys of a rosdep view that are ROS packages of the rosdistro (not system dependencies)."""
    keys = view.keys()  # a RosdepView: no iteration of its own
    return {key for key in keys if view.lookup(key).data.get("_is_ros")}


def resolve(view, context, keys: list[str]) -> dict[str, Resolution]:
    """Each key resolved by rosdep for the OS of ``context``, or the reason it does not resolve."""
    from rosdep2 import get_default_installer
    from rosdep2.lookup import ResolutionError

    _, installer_keys, default_key, os_name, os_version = get_default_installer(installer_context=context)
    os_spec = f"{os_name}:{os_version}"
    resolved = {}
    for key in keys:
        try:
            installer, rule = view.lookup(key).get_rule_for_platform(os_name, os_version, installer_keys, default_key)
            packages = tuple(str(p) for p in context.get_installer(installer).resolve(rule))
            resolved[key] = Resolution(installer, packages, "")
        except KeyError:
            resolved[key] = Resolution("", (), f"rosdep key {key} is not defined in rosdistro")
        except ResolutionError as exc:
            resolved[key] = Resolution("", (), f"rosdep key {key} does not resolve for {os_spec}: {exc.args[0]}")
    return resolved


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


def cmake_uses(root: Path, ros_packages: set[str]) -> list[Use]:
    """The find_package calls of the CMake files. In the package's CMakeLists.txt they need a build key, except under
    if(CATKIN_ENABLE_TESTING), where a test key does too, as in the CMake projects of test/ (sanitizers, fuzzing)."""
    uses = []
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
                    keys = (name,) if name in ros_packages else FIND_PACKAGE_KEYS.get(name)
                    uses.append(Use(f"find_package({name})", where, keys, kinds))
    return uses


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


def python_uses(root: Path, ros_packages: set[str]) -> list[Use]:
    """The third-party imports of the package's Python files. Unknown modules get ``keys`` None; pip-only modules
    get the pseudo-key ``pip:<distribution>``."""
    files = python_files(root)
    own = own_modules(files, root)
    uses = []
    for path in files:
        rel = path.relative_to(root)
        kinds = ("exec",) if rel.parts[0] in RUNTIME_TREES else ALL_KINDS
        for module, line in imported_modules(path):
            if module in own or module in UNDECLARED_MODULES or is_stdlib(module):
                continue
            if module in PIP_ONLY_MODULES:
                keys = (f"pip:{PIP_ONLY_MODULES[module]}",)
            else:
                keys = (module,) if module in ros_packages else MODULE_KEYS.get(module)
            uses.append(Use(f"import {module}", f"{rel}:{line}", keys, kinds))
    return uses


def pip_requirements(root: Path) -> dict[str, set[str]]:
    """The distributions of the pip requirements files as pseudo-keys ``pip:<name>``, with the kinds they serve."""
    requirements: dict[str, set[str]] = {}
    for name, kinds in REQUIREMENT_FILES.items():
        for line in (root / name).read_text().splitlines():
            match = re.match(r"\s*([A-Za-z0-9][A-Za-z0-9._-]*)", line.partition("#")[0])
            if match:
                key = "pip:" + re.sub(r"[-_.]+", "-", match.group(1).lower())
                requirements.setdefault(key, set()).update(kinds)
    return requirements


def uncovered(uses: list[Use], keys: dict[str, set[str]], package_xml: Path) -> list[str]:
    """A message for each use that no key (or pip requirement) of an acceptable kind covers."""
    problems = []
    for use in uses:
        if use.keys is None:
            problems.append(f"{use.where}: {use.what}: no rosdep key known for it (tables of tools/check_rosdep.py)")
        elif use.keys and not any(set(use.kinds) & keys.get(k, set()) for k in use.keys):
            problems.append(f"{use.where}: {use.what} needs {wanted(use, package_xml)}")
    return problems


def wanted(use: Use, package_xml: Path) -> str:
    """What would cover a use: a key of some kind in package.xml, or a line of a pip requirements file."""
    if use.keys[0].startswith("pip:"):
        files = [name for name, kinds in REQUIREMENT_FILES.items() if set(kinds) & set(use.kinds)]
        return f"{use.keys[0][4:]} in {' or '.join(files)} (pip only)"
    return f"{' or '.join(use.keys)} as {'/'.join(use.kinds)} key in {package_xml}"


def describe(packages: tuple[str, ...]) -> str:
    """Packages for the summary: space-separated, ``-`` when a rule installs nothing."""
    return " ".join(packages) or "-"


def check(args: argparse.Namespace) -> int:
    """Resolves every key, checks that the sources' dependencies are covered, prints the summary."""
    keys = package_keys(args.package_xml)
    view, context = rosdep_view(ROS_OS)
    ros_packages = ros_package_keys(view)
    system_keys = sorted(k for k in keys if k not in ros_packages)
    resolutions = {ROS_OS: resolve(view, context, sorted(keys))}
    for os_spec in SYSTEM_OSES:
        resolutions[os_spec] = resolve(*rosdep_view(os_spec), system_keys)
    problems = [f"{args.package_xml}: {r.error}" for by_key in resolutions.values() for r in by_key.values() if r.error]
    requirements = pip_requirements(ROOT)
    uses = cmake_uses(ROOT, ros_packages) + python_uses(ROOT, ros_packages)
    problems += uncovered(uses, {**keys, **requirements}, args.package_xml)
    for key in sorted(keys):
        columns = [
            f"{os_spec} {describe(by_key[key].packages)}" for os_spec, by_key in resolutions.items() if key in by_key
        ]
        print(f"{key} ({', '.join(sorted(keys[key]))}): {' | '.join(columns)}")
    for os_spec, by_key in resolutions.items():
        what = "keys" if os_spec == ROS_OS else "system keys"
        print(f"{os_spec}: {sum(not r.error for r in by_key.values())} of {len(by_key)} {what} resolved")
    print(f"{len(uses)} find_package calls and third-party imports checked against package.xml and the pip files")
    for problem in dict.fromkeys(problems):  # a key that rosdistro lacks, once, not once per OS
        print(f"check_rosdep: {problem}", file=sys.stderr)
    return 1 if problems else 0


def print_apt_names(args: argparse.Namespace) -> int:
    """Prints the apt packages the system keys of the chosen kinds resolve to for one OS, one a line."""
    view, context = rosdep_view(args.apt_names)
    resolutions = resolve(view, context, chosen_keys(args, ros_package_keys(view), ros=False))
    problems = [r.error for r in resolutions.values() if r.error]
    problems += [
        f"{k} resolves to the {r.installer} installer, not apt"
        for k, r in resolutions.items()
        if r.installer not in ("apt", "")
    ]
    for name in sorted({p for r in resolutions.values() if r.installer == "apt" for p in r.packages}):
        print(name)
    for problem in problems:
        print(f"check_rosdep: {args.package_xml}: {problem}", file=sys.stderr)
    return 1 if problems else 0


def print_ros_keys(args: argparse.Namespace) -> int:
    """Prints the keys of the chosen kinds that are ROS packages of the rosdistro, one a line."""
    for key in chosen_keys(args, ros_package_keys(rosdep_view(ROS_OS)[0]), ros=True):
        print(key)
    return 0


def chosen_keys(args: argparse.Namespace, ros_packages: set[str], ros: bool) -> list[str]:
    """The keys of package.xml of the kinds --kinds names: the ROS package keys, or the system keys."""
    keys = package_keys(args.package_xml)
    return sorted(k for k, kinds in keys.items() if (k in ros_packages) == ros and kinds & set(args.kinds))


def main(argv: list[str] | None = None) -> int:
    """Checks, or prints apt names (--apt-names) or ROS keys (--ros-keys)."""
    args = parse_args(argv)
    if importlib.util.find_spec("rosdep2") is None:
        print(
            "check_rosdep: rosdep's Python package is missing: `make setup` (Debian: apt-get install "
            "python3-rosdep2) or `pip install rosdep`",
            file=sys.stderr,
        )
        return 2
    missing = [name for name in ROSDISTRO_FILES if not (args.rosdistro_dir / name).is_file()]
    if missing:
        print(
            f"check_rosdep: {args.rosdistro_dir} lacks {', '.join(missing)} (see ../shared/rosdistro)", file=sys.stderr
        )
        return 2
    prepare_rosdep(args.rosdistro_dir, args.work_dir.resolve())
    if args.apt_names:
        return print_apt_names(args)
    return print_ros_keys(args) if args.ros_keys else check(args)


if __name__ == "__main__":
    sys.exit(main())
