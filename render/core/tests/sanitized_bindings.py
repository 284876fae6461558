"""Run pytest files against a sanitizer build of the bindings: `make sanitize`'s second half.

    LD_PRELOAD="$(gcc -print-file-name=libasan.so) $(gcc -print-file-name=libstdc++.so)" \\
    ASAN_OPTIONS=detect_leaks=0 python render/core/tests/sanitized_bindings.py BUILD_DIR TEST_FILE...

BUILD_DIR holds a `_core*.so` built with PTPB_SANITIZE=ON and PTPB_BUILD_PYTHON=ON; it is loaded
as render._core before any test imports the installed one. Python itself is not instrumented, so
the ASan runtime must come first (LD_PRELOAD), libstdc++ with it (otherwise ASan cannot find the
real __cxa_throw and aborts on the first C++ exception), and leak checking stays off (CPython
keeps its objects alive at exit on purpose).
"""

from __future__ import annotations

import importlib.util
import sys
from pathlib import Path


def load_sanitized_core(build_dir: Path) -> Path:
    candidates = sorted(build_dir.glob("_core*.so"))
    if not candidates:
        raise SystemExit(f"{build_dir}: no _core*.so; configure it with -DPTPB_BUILD_PYTHON=ON -DPTPB_SANITIZE=ON")
    spec = importlib.util.spec_from_file_location("render._core", candidates[0])
    if spec is None or spec.loader is None:
        raise SystemExit(f"{candidates[0]}: Python cannot load it as an extension module")
    module = importlib.util.module_from_spec(spec)
    sys.modules["render._core"] = module
    spec.loader.exec_module(module)
    return candidates[0]


def main() -> int:
    if len(sys.argv) < 3:
        raise SystemExit(__doc__)
    import pytest

    print(f"render._core <- {load_sanitized_core(Path(sys.argv[1]))}", flush=True)
    return pytest.main(["-q", "-p", "no:cacheprovider", *sys.argv[2:]])


if __name__ == "__main__":
    sys.exit(main())
