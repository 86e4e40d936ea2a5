"""Fixtures of the evloc package's tests: the build's tools, a simulated dataset with its exact
map, the shared real data, and a running evloc-localizer."""

import os
import re
import signal
import subprocess
import sys
import time

import pytest

PROJECT_ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
BUILD_DIR = os.environ.get("EVLOC_BUILD_DIR", os.path.join(PROJECT_ROOT, "build"))


def tool(relative):
    path = os.path.join(BUILD_DIR, relative)
    if not os.access(path, os.X_OK):
        pytest.fail(f"{path} is missing: build it first (make build)")
    return path


@pytest.fixture(scope="session")
def data_dir():
    """The shared real data (../shared/data or EVLOC_DATA_DIR); skips with the reason when
    absent, as the C++ tests do."""
    folder = os.environ.get("EVLOC_DATA_DIR",
                            os.path.join(os.path.dirname(PROJECT_ROOT), "shared", "data"))
    if not os.path.isdir(folder):
        pytest.skip(f"the shared real data is absent ({folder}; set EVLOC_DATA_DIR)")
    return folder


@pytest.fixture(scope="session")
def simulated(tmp_path_factory):
    """A 0.6 s evloc-sim dataset (events.evb, ground truth) with its exact map gt_map/."""
    folder = tmp_path_factory.mktemp("sim") / "dataset"
    subprocess.run([tool("tools/sim/evloc-sim"), "render", "--out", str(folder), "--motion",
                    "slow", "--duration", "0.6", "--seed", "3"], check=True,
                   stdout=subprocess.DEVNULL)
    return folder


@pytest.fixture(scope="session")
def cli_trajectory(simulated, tmp_path_factory):
    """evloc-track's trajectory file and stats of the simulated dataset."""
    folder = tmp_path_factory.mktemp("cli")
    out, stats = folder / "estimate.txt", folder / "stats.json"
    subprocess.run([tool("localizer/offline/evloc-track"), "--map", str(simulated / "gt_map"),
                    "--dataset", str(simulated), "--out", str(out), "--stats", str(stats),
                    "--quiet"], check=True)
    return out, stats


class Server:
    """evloc-localizer serve on a loopback port (0: any free one)."""

    def __init__(self, maps, log_path, port=0, extra=()):
        self.log_path = log_path
        self._log = open(log_path, "w", encoding="utf-8")  # pylint: disable=consider-using-with
        self.process = subprocess.Popen(  # pylint: disable=consider-using-with
            [tool("localizer/service/evloc-localizer"), "serve", "--maps", str(maps), "--listen",
             f"127.0.0.1:{port}", *extra], stdout=self._log, stderr=subprocess.STDOUT)
        deadline = time.monotonic() + 60
        self.port = None
        while time.monotonic() < deadline and self.port is None:
            with open(log_path, encoding="utf-8") as handle:
                found = re.search(r"serving on port (\d+)", handle.read())
            if found:
                self.port = int(found.group(1))
            elif self.process.poll() is not None:
                raise RuntimeError(f"evloc-localizer exited: {open(log_path).read()}")
            else:
                time.sleep(0.1)
        if self.port is None:
            self.stop()
            raise RuntimeError("evloc-localizer did not start within 60 s")

    @property
    def address(self):
        return f"127.0.0.1:{self.port}"

    def stop(self, sig=signal.SIGTERM):
        if self.process.poll() is None:
            self.process.send_signal(sig)
            try:
                self.process.wait(30)
            except subprocess.TimeoutExpired:
                self.process.kill()
                self.process.wait()
        self._log.close()


@pytest.fixture(scope="session")
def maps_folder(simulated, tmp_path_factory):
    """A maps folder holding the simulated exact map as `room`."""
    folder = tmp_path_factory.mktemp("maps")
    (folder / "room").mkdir()
    os.link(simulated / "gt_map" / "map.evmap", folder / "room" / "map.evmap")
    return folder


@pytest.fixture
def server(maps_folder, tmp_path):
    running = Server(maps_folder, tmp_path / "server.log")
    yield running
    running.stop()


sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
