"""Package metadata: the library imports from anywhere once set up; package.xml is a valid
format-3 manifest (parsed by catkin_pkg, as colcon and rosdep parse it) naming every
run-time dependency requirements.txt installs; setup.py installs what `ros2 launch` and
`ros2 run` look for."""

import configparser
import functools
import re
import subprocess
import sys
import xml.etree.ElementTree as ET
from pathlib import Path

from catkin_pkg.package import parse_package
from packaging.requirements import Requirement
from packaging.utils import canonicalize_name

from ato_nodes.cli import console
from ato_nodes.core.config.schema import NODES

ROOT = Path(__file__).resolve().parents[1]
PACKAGE = "ato_nodes"
# requirements.txt's packages that have a rosdep key (ros/rosdistro rosdep/*.yaml, or a ROS
# package); the others must be named in a comment of package.xml, one a line
ROSDEP_KEYS = {
    "ros-jazzy-rclpy": ("rclpy",),
    "ros-jazzy-common-interfaces": ("std_msgs", "geometry_msgs"),
    "rosbags": ("python3-rosbags-pip",),
    "mcap-ros2-support": ("mcap-ros2-support",),
    "numpy": ("python3-numpy",),
    "pyyaml": ("python3-yaml",),
    "matplotlib": ("python3-matplotlib",),
    "numba": ("python3-numba",),
    "pandas": ("python3-pandas",),
    "pytest": ("python3-pytest",),
    "catkin-pkg": ("python3-catkin-pkg",),
}
TEST_ONLY = {"pytest", "catkin-pkg"}


def requirements():
    lines = (line.split("#")[0].strip() for line in (ROOT / "requirements.txt").read_text()
             .splitlines())
    return [Requirement(line) for line in lines if line]


def manifest():
    warnings = []
    package = parse_package(ROOT / "package.xml", warnings=warnings)
    package.validate(warnings=warnings)
    return package, warnings


def test_the_library_imports_outside_the_repository(tmp_path):
    result = subprocess.run([sys.executable, "-c", "import ato_nodes.core.run.loop, ato_nodes; "
                             "print(ato_nodes.__file__)"], capture_output=True, text=True,
                            cwd=tmp_path, timeout=60)
    assert result.returncode == 0, result.stderr
    assert Path(result.stdout.strip()).is_relative_to(ROOT)


def test_package_xml_is_a_valid_format_3_ament_python_manifest():
    # catkin_pkg raises on XML that is not well-formed (colcon then silently builds the
    # package as plain Python, with no ament index entry for ros2 launch/run/pkg)
    package, warnings = manifest()
    assert warnings == []
    assert package.package_format == 3
    assert package.name == PACKAGE
    assert package.get_build_type() == "ament_python"
    assert [license.strip() for license in package.licenses] == ["Apache-2.0"]
    assert (ROOT / "LICENSE").read_text().lstrip().startswith("Apache License")


def test_package_xml_names_every_requirement():
    package, _ = manifest()
    run_keys = {dependency.name for dependency in package.exec_depends + package.run_depends}
    test_keys = {dependency.name for dependency in package.test_depends} | run_keys
    tree = ET.parse(ROOT / "package.xml", ET.XMLParser(target=ET.TreeBuilder(
        insert_comments=True)))
    comments = "\n".join(node.text for node in tree.iter() if node.tag is ET.Comment)
    for requirement in requirements():
        name = canonicalize_name(requirement.name)
        keys = ROSDEP_KEYS.get(name)
        if keys is None:  # pip only: a line of its own in a comment
            assert re.search(rf"^\s*{re.escape(requirement.name)}(\[[^\]]*\])?\s", comments,
                             re.MULTILINE | re.IGNORECASE), requirement.name
        else:
            missing = set(keys) - (test_keys if name in TEST_ONLY else run_keys)
            assert not missing, (requirement.name, missing)


def test_setup_py_installs_the_launch_file_configuration_and_ament_index_entry(tmp_path):
    # the install step colcon's ament_python build runs (its build log has the command)
    config = configparser.ConfigParser()
    config.read(ROOT / "setup.cfg")
    build, prefix = tmp_path / "build", tmp_path / "install"
    build.mkdir()
    result = subprocess.run(
        [sys.executable, "setup.py", "egg_info", "--egg-base", str(build),
         "build", "--build-base", str(build / "build"),
         "install", "--prefix", str(prefix), "--record", str(build / "install.log"),
         "--install-scripts", config["install"]["install_scripts"],
         "--single-version-externally-managed", "install_data"],
        cwd=ROOT, capture_output=True, text=True, timeout=300)
    assert result.returncode == 0, result.stderr
    share = prefix / "share" / PACKAGE
    assert (prefix / "share/ament_index/resource_index/packages" / PACKAGE).is_file()
    assert (share / "package.xml").read_bytes() == (ROOT / "package.xml").read_bytes()
    for folder in ("launch", "msg_config"):
        shipped = [path.relative_to(ROOT) for path in (ROOT / folder).rglob("*")
                   if path.is_file() and "__pycache__" not in path.parts]
        assert shipped
        for path in shipped:
            assert (share / path).read_bytes() == (ROOT / path).read_bytes(), path
    commands = [name for name, value in vars(console).items()
                if isinstance(value, functools.partial)]
    assert "run_stack" in commands
    for executable in (*NODES, *commands):  # where `ros2 run ato_nodes X` looks
        assert (prefix / "lib" / PACKAGE / executable).is_file(), executable
