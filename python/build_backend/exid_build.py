"""exid's in-tree build backend (PEP 517): `pip install .` builds a wheel of the Python package
`exid` by exid's own CMake build, with nothing but the standard library and CMake (no download
at build time: pyproject.toml's build-system requires nothing).

The wheel holds the package as `cmake --install` lays it out, made self-contained:

    exid/                        the Python files and the module _exid*.so (RUNPATH $ORIGIN/lib)
    exid/lib/                    libexid_core, libexid_dynamics, libexid_robots (by SONAME)
    exid/lib/exid/plugins/       the plugin libraries (found beside libexid_core, as installed)
    exid/share/                  examples/, data/ and robots/ (exid.data_path)

Its system libraries (yaml-cpp, fmt, Boost, ...) are Debian's: the wheel is for the system it
was built on (platform tag linux_<arch>), for the Python that runs the backend.

Environment:
    EXID_BUILD_DIR   an existing, configured build tree to build (the installed targets alone:
                     the program, the module, the plugins) and install from (CI reuses its
                     Release tree). Default: <source>/build-wheel, configured here (Release, no
                     tests, no benchmarks, Python on, for this interpreter).
    EXID_JOBS        parallel build jobs (default 2).
"""

from __future__ import annotations

import base64
import hashlib
import os
import re
import shutil
import subprocess
import sys
import sysconfig
import tempfile
import zipfile
from pathlib import Path
from typing import Dict, List, Optional, Tuple

SOURCE = Path(__file__).resolve().parents[2]


def _run(cmd: List[str]) -> None:
    print("exid_build:", " ".join(cmd), file=sys.stderr, flush=True)
    subprocess.run(cmd, check=True, stdout=sys.stderr)


def _cache(build: Path) -> Dict[str, str]:
    out = {}
    for line in (build / "CMakeCache.txt").read_text().splitlines():
        m = re.match(r"^([A-Za-z0-9_]+):[A-Z]+=(.*)$", line)
        if m:
            out[m.group(1)] = m.group(2)
    return out


def _interpreter() -> str:
    return os.path.realpath(getattr(sys, "_base_executable", None) or sys.executable)


def _build_tree() -> Path:
    given = os.environ.get("EXID_BUILD_DIR")
    if given:
        build = Path(given).resolve()
        if not (build / "CMakeCache.txt").is_file():
            raise RuntimeError(
                f"exid_build: EXID_BUILD_DIR={given} has no CMakeCache.txt; expected a configured "
                "exid build tree (cmake -S . -B build -DCMAKE_BUILD_TYPE=Release)"
            )
    else:
        build = SOURCE / "build-wheel"
        if not (build / "CMakeCache.txt").is_file():
            _run(
                [
                    "cmake", "-S", str(SOURCE), "-B", str(build), "-DCMAKE_BUILD_TYPE=Release",
                    "-DEXID_BUILD_TESTS=OFF", "-DEXID_BUILD_BENCHMARKS=OFF",
                    "-DEXID_BUILD_PYTHON=ON", f"-DPython3_EXECUTABLE={_interpreter()}",
                ]
            )
    # exid_installed_parts (CMakeLists.txt): the program, the module and every plugin, not the
    # tests and benchmarks of a full build tree, in one pass of make over the tree
    _run(["cmake", "--build", str(build), "-j", os.environ.get("EXID_JOBS", "2"), "--target",
          "exid_installed_parts"])
    return build


def _soname(lib: Path) -> Optional[str]:
    try:
        text = subprocess.run(
            ["readelf", "-d", str(lib)], check=True, capture_output=True, text=True
        ).stdout
    except (OSError, subprocess.CalledProcessError):
        return None
    m = re.search(r"\(SONAME\)\s+Library soname: \[([^\]]+)\]", text)
    return m.group(1) if m else None


def _layout(build: Path, stage: Path, root: Path) -> str:
    """Installs the build into `stage` and lays the wheel's files out in `root`; returns the
    version."""
    cache = _cache(build)
    _run(["cmake", "--install", str(build), "--prefix", str(stage)])
    libdir = stage / cache.get("CMAKE_INSTALL_LIBDIR", "lib")
    pydir = stage / cache.get("EXID_PYTHON_INSTALL_DIR", "lib/python3/dist-packages")
    pkg_src = pydir / "exid"
    if not pkg_src.is_dir():
        raise RuntimeError(
            f"exid_build: the build {build} installed no Python package (expected {pkg_src}); "
            "configure it with -DEXID_BUILD_PYTHON=ON (pybind11-dev, python3-dev, python3-numpy)"
        )
    suffix = sysconfig.get_config_var("EXT_SUFFIX")
    if not list(pkg_src.glob("_exid" + suffix)):
        found = [p.name for p in pkg_src.glob("_exid*.so")]
        raise RuntimeError(
            f"exid_build: the build {build} made {found} for {cache.get('Python3_EXECUTABLE')}; "
            f"expected _exid{suffix} for this interpreter ({_interpreter()})"
        )
    pkg = root / "exid"
    shutil.copytree(pkg_src, pkg, ignore=shutil.ignore_patterns("__pycache__"))
    # The data are in the package's share/ (exid.data_path), not where _layout.py says for an
    # installation under a prefix.
    (pkg / "_layout.py").write_text(
        '"""Where exid.data_path looks besides the package\'s share/: nowhere (a wheel)."""\n\n'
        "DATA_DIRS: list = []\n"
    )
    # The project's shared libraries, each under its SONAME (the name the loader asks for).
    (pkg / "lib").mkdir()
    for f in sorted(libdir.glob("libexid_*.so*")):
        if f.is_symlink() or not f.is_file():
            continue
        shutil.copy2(f, pkg / "lib" / (_soname(f) or f.name))
    shutil.copytree(libdir / "exid" / "plugins", pkg / "lib" / "exid" / "plugins")
    shutil.copytree(stage / (cache.get("CMAKE_INSTALL_DATADIR") or "share") / "exid", pkg / "share")
    return cache.get("CMAKE_PROJECT_VERSION", "0")


def _tag() -> str:
    py = f"cp{sys.version_info[0]}{sys.version_info[1]}"
    plat = sysconfig.get_platform().replace("-", "_").replace(".", "_")
    return f"{py}-{py}-{plat}"


def _metadata(version: str) -> str:
    return (
        "Metadata-Version: 2.1\n"
        "Name: exid\n"
        f"Version: {version}\n"
        "Summary: Experimental identification of robot and payload dynamics (exid's Python "
        "package, with its core and plugins)\n"
        "License: see LICENSE\n"
        f"Requires-Python: =={sys.version_info[0]}.{sys.version_info[1]}.*\n"
        "Requires-Dist: numpy\n"
        "Provides-Extra: pandas\n"
        "Requires-Dist: pandas; extra == \"pandas\"\n"
    )


def _record_line(name: str, data: bytes) -> str:
    digest = base64.urlsafe_b64encode(hashlib.sha256(data).digest()).rstrip(b"=").decode()
    return f"{name},sha256={digest},{len(data)}"


def _write_wheel(root: Path, version: str, wheel_directory: str) -> str:
    name = f"exid-{version}-{_tag()}.whl"
    info = f"exid-{version}.dist-info"
    files: List[Tuple[str, Path]] = sorted(
        (p.relative_to(root).as_posix(), p) for p in root.rglob("*") if p.is_file()
    )
    extra = {
        f"{info}/METADATA": _metadata(version).encode(),
        f"{info}/WHEEL": (
            "Wheel-Version: 1.0\nGenerator: exid_build\nRoot-Is-Purelib: false\n"
            f"Tag: {_tag()}\n"
        ).encode(),
        f"{info}/top_level.txt": b"exid\n",
        f"{info}/LICENSE": (SOURCE / "LICENSE").read_bytes(),
    }
    record = []
    path = Path(wheel_directory) / name
    with zipfile.ZipFile(path, "w", compression=zipfile.ZIP_DEFLATED) as z:
        for arc, p in files:
            data = p.read_bytes()
            zi = zipfile.ZipInfo(arc, date_time=(2020, 1, 1, 0, 0, 0))
            zi.external_attr = (p.stat().st_mode & 0o777 | 0o100000) << 16
            zi.compress_type = zipfile.ZIP_DEFLATED
            z.writestr(zi, data)
            record.append(_record_line(arc, data))
        for arc, data in extra.items():
            z.writestr(zipfile.ZipInfo(arc, date_time=(2020, 1, 1, 0, 0, 0)), data)
            record.append(_record_line(arc, data))
        record.append(f"{info}/RECORD,,")
        z.writestr(
            zipfile.ZipInfo(f"{info}/RECORD", date_time=(2020, 1, 1, 0, 0, 0)),
            "\n".join(record) + "\n",
        )
    return name


# ---------------------------------------------------------------- PEP 517 hooks
def get_requires_for_build_wheel(config_settings=None):  # noqa: ANN001
    return []


def _source_version() -> str:
    m = re.search(r"project\(exid\s+VERSION\s+([0-9.]+)", (SOURCE / "CMakeLists.txt").read_text())
    if not m:
        raise RuntimeError("exid_build: no project(exid VERSION x.y.z) in CMakeLists.txt")
    return m.group(1)


def prepare_metadata_for_build_wheel(metadata_directory, config_settings=None):  # noqa: ANN001
    """The metadata without building (pip asks for it first)."""
    info = Path(metadata_directory) / f"exid-{_source_version()}.dist-info"
    info.mkdir(parents=True, exist_ok=True)
    (info / "METADATA").write_text(_metadata(_source_version()))
    return info.name


def build_wheel(wheel_directory, config_settings=None, metadata_directory=None):  # noqa: ANN001
    build = _build_tree()
    with tempfile.TemporaryDirectory(prefix="exid-wheel-") as tmp:
        root = Path(tmp) / "root"
        root.mkdir()
        version = _layout(build, Path(tmp) / "stage", root)
        return _write_wheel(root, version, wheel_directory)
