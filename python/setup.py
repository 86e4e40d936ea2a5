"""Packages evloc for Python (docs/python.md), offline, from a built evloc tree.

The C++ module `evloc._evloc` is built by the project's CMake (target evloc_python, `make build`);
this script copies it from the build folder (EVLOC_BUILD_DIR, default ../build) into the package
and generates the gRPC stubs of the service from ../proto with protoc and grpc_python_plugin
(generate_stubs) into the package: nothing is downloaded and no stub is checked in.

    python3 -m venv --system-site-packages .venv
    .venv/bin/pip install --no-build-isolation ./python
"""

import glob
import os
import shutil
import subprocess

from setuptools import setup
from setuptools.command.build_py import build_py

HERE = os.path.dirname(os.path.abspath(__file__))
PROJECT_ROOT = os.path.dirname(HERE)
PROTO_FILES = ("evloc/map.proto", "evloc/localizer.proto")


def build_dir():
    return os.path.abspath(os.environ.get("EVLOC_BUILD_DIR", os.path.join(PROJECT_ROOT, "build")))


def find_module():
    """The built evloc._evloc for this interpreter, or a SystemExit saying how to build it."""
    folder = os.path.join(build_dir(), "python")
    import sysconfig  # pylint: disable=import-outside-toplevel
    suffix = sysconfig.get_config_var("EXT_SUFFIX")
    path = os.path.join(folder, "_evloc" + suffix)
    if not os.path.isfile(path):
        found = sorted(glob.glob(os.path.join(folder, "_evloc*.so")))
        hint = (" (found " + ", ".join(os.path.basename(f) for f in found) +
                ": built for another Python; evloc builds for /usr/bin/python3)") if found else ""
        raise SystemExit(
            f"evloc setup.py: error: the C++ module {path} is missing{hint}. Build it first with "
            f"'make build' in {PROJECT_ROOT} (target evloc_python; needs pybind11-dev from "
            f"scripts/install-deps.sh), or set EVLOC_BUILD_DIR to the build folder.")
    return path


def generate_stubs(out_dir):
    """Generates evloc/map_pb2.py, localizer_pb2.py and localizer_pb2_grpc.py into out_dir with
    Debian's protoc (protobuf-compiler, 3.21: the version of the python3-protobuf runtime) and
    grpc_python_plugin (protobuf-compiler-grpc). Debian 12's grpc_tools module carries protoc
    3.5.1, which refuses the proto3 `optional` fields of localizer.proto, so it is not used."""
    proto_root = os.path.abspath(os.environ.get("EVLOC_PROTO_DIR",
                                                os.path.join(PROJECT_ROOT, "proto")))
    for name in PROTO_FILES:
        if not os.path.isfile(os.path.join(proto_root, name)):
            raise SystemExit(f"evloc setup.py: error: {os.path.join(proto_root, name)} is missing "
                             "(set EVLOC_PROTO_DIR to the project's proto/ folder)")
    protoc = shutil.which(os.environ.get("EVLOC_PROTOC", "protoc"))
    plugin = shutil.which(os.environ.get("EVLOC_GRPC_PYTHON_PLUGIN", "grpc_python_plugin"))
    if protoc is None or plugin is None:
        raise SystemExit("evloc setup.py: error: protoc and grpc_python_plugin are needed to "
                         "generate the service stubs (Debian: protobuf-compiler, "
                         "protobuf-compiler-grpc; run scripts/install-deps.sh)")
    command = [protoc, "-I", proto_root, "--python_out=" + out_dir,
               "--grpc_python_out=" + out_dir, "--plugin=protoc-gen-grpc_python=" + plugin,
               *PROTO_FILES]
    result = subprocess.run(command, check=False)
    if result.returncode != 0:
        raise SystemExit("evloc setup.py: error: " + " ".join(command) + " failed with status "
                         f"{result.returncode} (see the messages above)")


class BuildPy(build_py):
    """build_py plus the C++ module and the generated stubs."""

    def run(self):
        super().run()
        package_dir = os.path.join(self.build_lib, "evloc")
        os.makedirs(package_dir, exist_ok=True)
        module = find_module()
        shutil.copy2(module, os.path.join(package_dir, os.path.basename(module)))
        # The stubs import each other as `evloc.map_pb2` (the proto package path is evloc/), which
        # is this package: they go next to its modules.
        generate_stubs(self.build_lib)


setup(
    name="evloc",
    version="0.1.0",
    description="evloc: map-based localization of event cameras (bindings, service client, "
                "trajectories)",
    packages=["evloc"],
    python_requires=">=3.9",
    install_requires=[],  # numpy, grpcio, protobuf: Debian's (python3-numpy, python3-grpcio, ...)
    cmdclass={"build_py": BuildPy},
    options={"build": {"build_base": os.path.join(build_dir(), "python", "setuptools")},
             "egg_info": {"egg_base": os.path.join(build_dir(), "python")}},
    has_ext_modules=lambda: True,
    zip_safe=False,
)
