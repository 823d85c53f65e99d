"""`rig console` as the operator starts it: a subprocess that prints its URL, serves, and stops on Ctrl-C.

Ctrl-C (SIGINT) must shut the app down through its lifespan, which stops the jobs and closes the
devices, and exit cleanly: status 0 (or 130, the shell's code for an interrupt), no traceback.
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import threading
import urllib.request
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
STARTUP_S = 120  # a bound on a loaded machine, not a timing assertion
SHUTDOWN_S = 60


@pytest.mark.skipif(sys.platform == "win32", reason="SIGINT to a child process is POSIX")
def test_ctrl_c_closes_the_devices_and_exits_cleanly(tmp_path: Path) -> None:
    (tmp_path / "rig.toml").write_text("[camera]\nsize = [160, 120]\n[projector]\nsize = [228, 285]\n")
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(filter(None, [str(ROOT), os.environ.get("PYTHONPATH")]))}
    process = subprocess.Popen(
        [
            sys.executable,
            "-m",
            "rig.cli",
            "-v",
            "console",
            "--config",
            str(tmp_path / "rig.toml"),
            "--data",
            str(tmp_path / "data"),
            "--port",
            "0",
        ],
        cwd=tmp_path,
        env=env,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    try:
        lines: list[str] = []
        found = threading.Event()

        def read_stdout() -> None:
            assert process.stdout is not None
            for line in process.stdout:
                lines.append(line)
                if line.startswith("rig console: http://"):
                    found.set()

        reader = threading.Thread(target=read_stdout, daemon=True)
        reader.start()
        assert found.wait(STARTUP_S), f"no URL printed: {lines!r}"
        url = next(line for line in lines if line.startswith("rig console: ")).split(": ", 1)[1].strip()
        with urllib.request.urlopen(url + "api/devices", timeout=30) as reply:
            devices = json.load(reply)
        assert [d["state"] for d in devices["devices"]] == ["open", "open", "open"]

        process.send_signal(signal.SIGINT)
        status = process.wait(timeout=SHUTDOWN_S)
        stderr = process.stderr.read() if process.stderr else ""
    finally:
        if process.poll() is None:
            process.kill()
            process.wait()
    assert status in (0, 130), (status, stderr)
    assert "Traceback" not in stderr, stderr
    assert "console: rig open" in stderr and "console: rig closed" in stderr, stderr
