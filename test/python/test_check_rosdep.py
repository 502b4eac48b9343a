"""tools/check_rosdep.py: package.xml's keys resolve offline with rosdep, and it fails, naming the key or the use,
when a key does not resolve or when a find_package or an import is left uncovered.

The tool runs on the package's own sources with a modified copy of package.xml (--package-xml), against
../shared/rosdistro (skipped when absent), with rosdep's cache in a temporary directory filled once for the module.
"""

from __future__ import annotations

import importlib.util
import re
import subprocess
import sys
from pathlib import Path

import pytest
from dependency_scan import imported_modules, is_stdlib, own_modules, python_files  # tools/, on the path in conftest

ROOT = Path(__file__).resolve().parents[2]
TOOL = ROOT / "tools" / "check_rosdep.py"
ROSDISTRO = ROOT.parent / "shared" / "rosdistro"
PACKAGE_XML = (ROOT / "package.xml").read_text()

if not ROSDISTRO.is_dir():
    MISSING = f"needs the rosdistro copy at {ROSDISTRO} (absent)"
elif importlib.util.find_spec("rosdep2") is None:
    MISSING = "needs rosdep's Python package (python3-rosdep2: `make setup`)"
else:
    MISSING = ""
needs_rosdep = pytest.mark.skipif(bool(MISSING), reason=MISSING)


def run_tool(work_dir: Path, *args: str) -> subprocess.CompletedProcess:
    """The tool's run with rosdep's cache in ``work_dir``."""
    command = [sys.executable, str(TOOL), "--rosdistro-dir", str(ROSDISTRO), "--work-dir", str(work_dir), *args]
    return subprocess.run(command, capture_output=True, text=True, timeout=120, check=False)


@pytest.fixture(scope="module")
def work_dir(tmp_path_factory) -> Path:
    """rosdep's sources list and cache, updated once by a first run of the tool."""
    path = tmp_path_factory.mktemp("rosdep")
    first = run_tool(path, "--apt-names", "ubuntu:focal")
    assert first.returncode == 0, first.stderr
    return path


@pytest.fixture(scope="module")
def real_run(work_dir: Path) -> subprocess.CompletedProcess:
    """The tool on the real package.xml."""
    return run_tool(work_dir)


def edited_package_xml(tmp_path: Path, old: str, new: str) -> Path:
    """A copy of package.xml with ``old`` (present once) replaced by ``new``."""
    assert PACKAGE_XML.count(old) == 1, old
    path = tmp_path / "package.xml"
    path.write_text(PACKAGE_XML.replace(old, new))
    return path


@needs_rosdep
def test_real_package_xml_passes(real_run):
    assert real_run.returncode == 0, real_run.stderr
    assert real_run.stderr == ""
    counts = {}
    for line in real_run.stdout.splitlines():
        match = re.fullmatch(r"(\w+:\w+): (\d+) of (\d+) (system )?keys resolved", line)
        if match:
            counts[match.group(1)] = (int(match.group(2)), int(match.group(3)))
    assert set(counts) == {"ubuntu:focal", "debian:bookworm", "debian:bullseye"}
    assert all(resolved == total > 10 for resolved, total in counts.values())


@needs_rosdep
def test_ros_package_keys_resolve_for_focal_only(real_run):
    roscpp = next(line for line in real_run.stdout.splitlines() if line.startswith("roscpp "))
    assert roscpp == "roscpp (build, build_export, exec): ubuntu:focal ros-noetic-roscpp"
    ceres = next(line for line in real_run.stdout.splitlines() if line.startswith("libceres-dev "))
    assert "ubuntu:focal libceres-dev | debian:bookworm libceres-dev | debian:bullseye libceres-dev" in ceres


@needs_rosdep
def test_removed_key_leaves_find_package_uncovered(work_dir, tmp_path):
    package_xml = edited_package_xml(tmp_path, "<depend>libceres-dev</depend>", "")
    result = run_tool(work_dir, "--package-xml", str(package_xml))
    assert result.returncode == 1
    assert f"CMakeLists.txt:{cmake_line('find_package(Ceres')}: find_package(Ceres) needs libceres-dev" in result.stderr
    assert str(package_xml) in result.stderr


@needs_rosdep
def test_exec_import_needs_exec_key(work_dir, tmp_path):
    package_xml = edited_package_xml(
        tmp_path, "<exec_depend>python3-tqdm</exec_depend>", "<test_depend>python3-tqdm</test_depend>"
    )
    result = run_tool(work_dir, "--package-xml", str(package_xml))
    assert result.returncode == 1
    assert "import tqdm needs python3-tqdm as exec key" in result.stderr
    assert "src/grid_puzzle_localization/" in result.stderr


@needs_rosdep
def test_bogus_key_does_not_resolve(work_dir, tmp_path):
    package_xml = edited_package_xml(
        tmp_path,
        "<test_depend>rostest</test_depend>",
        "<test_depend>rostest</test_depend>\n<exec_depend>gpl-bogus</exec_depend>",
    )
    result = run_tool(work_dir, "--package-xml", str(package_xml))
    assert result.returncode == 1
    assert result.stderr.count("rosdep key gpl-bogus is not defined in rosdistro") == 1
    assert "gpl-bogus (exec)" in result.stdout


@needs_rosdep
def test_apt_names_for_bullseye(work_dir):
    result = run_tool(work_dir, "--apt-names", "debian:bullseye")
    assert result.returncode == 0, result.stderr
    names = result.stdout.split()
    assert {"libceres-dev", "libcurl4-openssl-dev", "libpcl-dev", "python3-pytest", "python3-numpy"} <= set(names)
    assert names == sorted(set(names))
    assert not [n for n in names if n.startswith("ros-")]  # ROS packages: Debian's own names, not rosdep's


@needs_rosdep
def test_apt_names_of_one_kind(work_dir):
    result = run_tool(work_dir, "--apt-names", "debian:bookworm", "--kinds", "test")
    assert result.returncode == 0, result.stderr
    assert "libpcl-dev" in result.stdout.split()
    assert "nlohmann-json3-dev" not in result.stdout.split()


@needs_rosdep
def test_ros_keys(work_dir):
    result = run_tool(work_dir, "--ros-keys", "--kinds", "build")
    assert result.returncode == 0, result.stderr
    keys = result.stdout.split()
    assert {"catkin", "roscpp", "message_generation", "pluginlib"} <= set(keys)
    assert "rostest" not in keys  # a test key
    assert "libceres-dev" not in keys  # a system key


def cmake_line(text: str) -> int:
    """The line of CMakeLists.txt where ``text`` first appears."""
    lines = (ROOT / "CMakeLists.txt").read_text().splitlines()
    return next(n for n, line in enumerate(lines, 1) if text in line)


@pytest.mark.parametrize("module", ["json", "xml", "importlib", "_thread", "sys", "sqlite3", "__future__"])
def test_stdlib_fallback_finds_stdlib(monkeypatch, module):
    monkeypatch.delattr(sys, "stdlib_module_names", raising=False)
    assert is_stdlib(module)


@pytest.mark.parametrize("module", ["numpy", "yaml", "pytest", "no_such_module_anywhere"])
def test_stdlib_fallback_leaves_out_installed_modules(monkeypatch, module):
    monkeypatch.delattr(sys, "stdlib_module_names", raising=False)
    assert not is_stdlib(module)


@pytest.mark.skipif(sys.version_info < (3, 10), reason="compares with sys.stdlib_module_names (Python 3.10)")
def test_stdlib_fallback_agrees_on_the_package_imports(monkeypatch):
    files = python_files(ROOT)
    modules = {module for path in files for module, _ in imported_modules(path)} - own_modules(files, ROOT)
    expected = {module for module in modules if is_stdlib(module)}  # by sys.stdlib_module_names
    monkeypatch.delattr(sys, "stdlib_module_names")
    assert {module for module in modules if is_stdlib(module)} == expected
    assert {"json", "subprocess", "numpy"} <= modules
