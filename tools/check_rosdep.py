#!/usr/bin/env python3
"""Checks package.xml against rosdep and against what the package uses, offline.

Every key of package.xml is resolved with rosdep against the rosdistro copy in ../shared/rosdistro: all keys for
Ubuntu 20.04 with ROS Noetic (where the ROS package keys resolve to ros-noetic-*), the system keys (every key that
is not a ROS package) for Debian 12 and Debian 11 too (Debian names its ROS packages itself, which rosdistro does
not list). Then every find_package of the CMake files and every import of a third-party Python module of
src/grid_puzzle_localization, scripts, tools, bench and test must be covered by a key of a kind that fits: code
that the package runs (src/, scripts/) needs an exec key, the build outside its tests a build key. The sources are
read by tools/dependency_scan.py; this tool maps what they use to keys and resolves the keys.

    check_rosdep.py                              # check; print the keys and their packages
    check_rosdep.py --apt-names debian:bullseye  # the apt packages of the system keys, one a line
    check_rosdep.py --ros-keys                   # the keys that are ROS packages, one a line

Needs rosdep's Python package (Debian: python3-rosdep2, which `make setup` installs; elsewhere pip's rosdep).
Exit status: 0 when everything resolves and is covered, 1 when not (each problem on stderr), 2 on bad usage.
"""

from __future__ import annotations

import argparse
import hashlib
import importlib.util
import os
import re
import sys
import xml.etree.ElementTree as ET
from pathlib import Path
from typing import NamedTuple

from dependency_scan import ALL_KINDS, find_packages, third_party_imports

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


def cmake_uses(root: Path, ros_packages: set[str]) -> list[Use]:
    """The find_package calls of the CMake files (dependency_scan.find_packages) with the keys that provide what
    they find: a ROS package's own name, else FIND_PACKAGE_KEYS (None: unknown)."""
    return [
        Use(d.what, d.where, (d.name,) if d.name in ros_packages else FIND_PACKAGE_KEYS.get(d.name), d.kinds)
        for d in find_packages(root)
    ]


def python_uses(root: Path, ros_packages: set[str]) -> list[Use]:
    """The third-party imports of the package's Python files (dependency_scan.third_party_imports) but those of
    UNDECLARED_MODULES, with their keys. Unknown modules get ``keys`` None; pip-only modules get the pseudo-key
    ``pip:<distribution>``."""
    uses = []
    for d in third_party_imports(root, frozenset(UNDECLARED_MODULES)):
        if d.name in PIP_ONLY_MODULES:
            keys = (f"pip:{PIP_ONLY_MODULES[d.name]}",)
        else:
            keys = (d.name,) if d.name in ros_packages else MODULE_KEYS.get(d.name)
        uses.append(Use(d.what, d.where, keys, d.kinds))
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
