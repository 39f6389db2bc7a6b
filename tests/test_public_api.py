"""No private module of a dependency is imported (``typer._click``, ``numpy._core``, ...): pyproject's tested
ranges promise only the public API, which a new release keeps."""

from __future__ import annotations

import re
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
# ``import numpy._core...``, ``from typer._click import ...``, ``from typer import _click``: a name after a dot,
# or imported from a package, that begins with an underscore; locoplan's own (relative) modules are its business
PRIVATE = re.compile(r"^\s*(?:from\s+(?!\.)(?!locoplan\b)[\w.]*\._\w*|import\s+(?!locoplan\b)[\w.]*\._\w*"
                     r"|from\s+(?!\.)(?!locoplan\b)[\w.]+\s+import\s+\(?\s*_(?!_)\w*)", re.M)


def test_no_private_api_of_a_dependency():
    folders = ("locoplan", "tests", "benchmarks")
    local = {f.stem for folder in folders[1:] for f in (ROOT / folder).glob("*.py")}  # helper modules beside the scripts
    found = [f"{f.relative_to(ROOT)}: {m.group(0).strip()}"
             for folder in folders for f in sorted((ROOT / folder).rglob("*.py"))
             for m in PRIVATE.finditer(f.read_text(encoding="utf-8"))
             if m.group(0).split()[1].split(".")[0] not in local]
    assert found == []


def test_the_pattern_finds_private_imports():
    for line in ("from numpy._core.multiarray import interp", "    from typer._click.globals import x",
                 "from typer import _click as click", "import numpy._core.multiarray"):
        assert PRIVATE.search(line), line
    for line in ("from ._private import x", "from ..sim.native import _Checked", "from locoplan.sim import native",
                 "from locoplan.sim.native import _tolerant", "from __future__ import annotations", "import numpy as np"):
        assert not PRIVATE.search(line), line
