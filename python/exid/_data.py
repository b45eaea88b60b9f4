"""exid.data_path: the examples, data sets and robot files that come with the package, wherever
it is installed (a wheel's share/, an installation's <prefix>/share/exid, the source tree for the
build tree's package)."""

from __future__ import annotations

import os
from pathlib import Path
from typing import List

from . import _layout


def data_dirs() -> List[Path]:
    """The folders searched, in order: $EXID_DATA_DIR when set, the package's share/ (a wheel),
    then where the build put them (python/CMakeLists.txt, _layout.py)."""
    here = Path(__file__).resolve().parent
    dirs = []
    if os.environ.get("EXID_DATA_DIR"):
        dirs.append(Path(os.environ["EXID_DATA_DIR"]))
    dirs.append(here / "share")
    dirs += [(here / d).resolve() for d in _layout.DATA_DIRS]
    return [d for d in dirs if d.is_dir()]


def data_path(*parts: str) -> Path:
    """A file shipped with exid, by its path in the source tree: ``exid.data_path(
    "examples/real/tx40_wls.yaml")``, ``data_path("data/staubli_tx40/urdf/tx40_mdh_modified.urdf")``,
    ``data_path("robots/tx40/tx40_exid.xml")``; without arguments, the folder holding
    ``examples/``, ``data/`` and ``robots/``. Raises FileNotFoundError naming where it looked."""
    rel = Path(*parts) if parts else Path(".")
    dirs = data_dirs()
    for d in dirs:
        if (d / rel).exists():
            return d / rel
    looked = ", ".join(str(d) for d in dirs) or "no folder (none of the package's data folders exists)"
    raise FileNotFoundError(
        f"exid.data_path: {rel.as_posix()} is not among exid's files; looked in {looked} "
        "(examples/, data/ and robots/ as in the source tree)"
    )
