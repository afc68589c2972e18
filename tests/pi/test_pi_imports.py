"""The Pi libraries stay out of the process unless the Pi backend is chosen."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]


def test_core_pi_config_and_service_do_not_import_gpiozero_or_smbus2():
    code = (
        "import sys\n"
        "import robot, robot.hardware, robot.config\n"
        "import robot.pi, robot.pi.config, robot.pi.safety, robot.pi.check\n"
        "import server.main, server.hardware, server.runs\n"  # the service, until a Pi run opens the robot
        "loaded = sorted(m for m in ('gpiozero', 'smbus2', 'lgpio') if m in sys.modules)\n"
        "print(','.join(loaded))\n"
    )
    result = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True, check=True)
    assert result.stdout.strip() == ""


def test_the_drivers_do_import_gpiozero_when_chosen():
    code = "import sys\nfrom robot.pi import PiHardware\nprint('gpiozero' in sys.modules)\n"
    result = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True, check=True)
    assert result.stdout.strip() == "True"
