"""Loads the C++ module evloc._evloc (built by the project's CMake, target evloc_python).

An installed package carries it; a source checkout finds it in EVLOC_PYTHON_MODULE_DIR (the build
folder's python/, as the ctest test sets it)."""

import importlib.util
import os
import sys

try:
    from evloc import _evloc  # pylint: disable=no-name-in-module
except ImportError as _missing:
    _folder = os.environ.get("EVLOC_PYTHON_MODULE_DIR")
    _found = None
    if _folder:
        import sysconfig
        _path = os.path.join(_folder, "_evloc" + sysconfig.get_config_var("EXT_SUFFIX"))
        if os.path.isfile(_path):
            _spec = importlib.util.spec_from_file_location("evloc._evloc", _path)
            _found = importlib.util.module_from_spec(_spec)
            sys.modules["evloc._evloc"] = _found
            _spec.loader.exec_module(_found)
    if _found is None:
        raise ImportError(
            "evloc: the C++ module evloc._evloc is missing: install the package from a built tree "
            "(make build; pip install --no-build-isolation ./python, docs/python.md) or set "
            f"EVLOC_PYTHON_MODULE_DIR to the build's python/ folder ({_missing})") from _missing
    _evloc = _found

Error = _evloc.Error
InvalidArgumentError = _evloc.InvalidArgumentError
IoError = _evloc.IoError
ParseError = _evloc.ParseError
event_dtype = _evloc.event_dtype
