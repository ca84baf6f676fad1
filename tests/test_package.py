"""Package metadata: the library imports from anywhere once set up, and package.xml names
every run-time dependency the nodes import."""

import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def test_the_library_imports_outside_the_repository(tmp_path):
    result = subprocess.run([sys.executable, "-c", "import ato_nodes.core.loop, ato_nodes; "
                             "print(ato_nodes.__file__)"], capture_output=True, text=True,
                            cwd=tmp_path, timeout=60)
    assert result.returncode == 0, result.stderr
    assert Path(result.stdout.strip()).is_relative_to(ROOT)


def test_package_xml_names_every_run_time_dependency():
    text = (ROOT / "package.xml").read_text()
    for key in ("rclpy", "std_msgs", "geometry_msgs", "rosgraph_msgs", "python3-numpy",
                "python3-scipy", "python3-yaml", "python3-matplotlib"):
        assert f"<exec_depend>{key}</exec_depend>" in text, key
    for pip_only in ("rosbags", "mcap-ros2-support", "daqp"):  # noted for pip
        assert f"{pip_only} " in text, pip_only
    assert (ROOT / "LICENSE").read_text().lstrip().startswith("Apache License")
    assert "<license>Apache-2.0</license>" in text
