"""Machine description written into every benchmark's JSON (shared by the benchmark scripts)."""

import os
import platform


def machine() -> dict:
    """Platform, processor, cores, Python, CPU model (Linux) and the 1-minute load average when known."""
    info = {"platform": platform.platform(), "processor": platform.processor() or platform.machine(),
            "cpu_count": os.cpu_count(), "python": platform.python_version()}
    try:
        with open("/proc/cpuinfo") as fh:
            for line in fh:
                if line.startswith("model name"):
                    info["cpu_model"] = line.split(":", 1)[1].strip()
                    break
    except OSError:
        pass
    try:
        info["load_average_1min"] = os.getloadavg()[0]
    except OSError:
        pass
    return info
