"""Packaging: an ordinary install pulls in nothing that only works on a Raspberry Pi."""

from __future__ import annotations

import re
import tomllib
from pathlib import Path

PYPROJECT = Path(__file__).resolve().parent.parent / "pyproject.toml"
PI_ONLY = ("lgpio", "rpi.gpio", "rpi-gpio", "pigpio", "rpi-lgpio")


def _name(requirement: str) -> str:
    return re.split(r"[\s<>=!~;\[]", requirement.strip(), maxsplit=1)[0].lower()


def test_base_dependencies_hold_no_pi_only_package() -> None:
    project = tomllib.loads(PYPROJECT.read_text())["project"]
    names = {_name(r) for r in project["dependencies"]}
    assert not names & set(PI_ONLY)
    assert {"gpiozero", "smbus2", "filterpy", "fastapi", "numpy"} <= names  # pure Python or wheels everywhere


def test_pi_packages_install_only_on_arm() -> None:
    extras = tomllib.loads(PYPROJECT.read_text())["project"]["optional-dependencies"]
    for requirement in extras["pi"]:
        assert _name(requirement) in PI_ONLY
        assert "platform_machine" in requirement and "aarch64" in requirement
    for extra, requirements in extras.items():
        if extra != "pi":
            assert not {_name(r) for r in requirements} & set(PI_ONLY), extra


def test_console_script_and_module_entry_point() -> None:
    project = tomllib.loads(PYPROJECT.read_text())["project"]
    assert project["name"] == "sonarslam"
    assert project["scripts"]["sonarslam"] == "robot.cli:main"
    assert (PYPROJECT.parent / "robot" / "__main__.py").exists()
