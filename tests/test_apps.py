"""Every example in apps/ runs headless and ends with a check of its final state."""

import os
import subprocess
import sys

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def test_headless_hang_example():
    proc = subprocess.run([sys.executable, os.path.join(ROOT, "apps", "headless_hang.py"), "--frames", "6",
                           "--strands", "30"], capture_output=True, text=True, timeout=600)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert "OK" in proc.stdout
