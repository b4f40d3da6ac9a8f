"""Result tables generated from the committed study CSVs, never typed: each table is a function of its CSV's
rows, written into the documents between the markers `<!-- table:NAME -->` and `<!-- /table:NAME -->`. Each
study's folder owns its tables (`benchmarks/STUDY/tables.py`, the lab notebook's `notebook/tables.py`), and its
README the command that makes its CSV.

    python benchmarks/doc_tables.py            # regenerate every table of the documents (`make tables`)
    python benchmarks/doc_tables.py --check    # change nothing; exit 2 when a table is out of date
    python benchmarks/doc_tables.py --list     # each table the README and docs/ show: its folder, its command

The documentation's tool, not the library's: no module of dpi/ writes a document."""

from __future__ import annotations

import argparse
import importlib
import importlib.util
import re
import sys
from collections.abc import Callable
from pathlib import Path

BENCHMARKS = Path(__file__).resolve().parent
CHECKOUT = BENCHMARKS.parent
DOCUMENTS = (Path("README.md"), Path("docs") / "studies.md", Path("docs") / "priors.md", Path("notebook") / "log.md",
             Path("notebook") / "studies.md", Path("notebook") / "priors.md")
"""the documents whose tables are generated, relative to a checkout's root, besides each study folder's README"""


def documents(root: Path) -> list[Path]:
    """Every document with generated tables under `root`: DOCUMENTS, then benchmarks/*/README.md."""
    return [*DOCUMENTS, *(p.relative_to(root) for p in sorted((root / "benchmarks").glob("*/README.md")))]
NOTEBOOK_TABLES = CHECKOUT / "notebook" / "tables.py"
"""the lab notebook's tables (its dev sweeps and diagnostics)"""

Table = Callable[[Path], str]


def table_modules() -> dict[Path, dict[str, Table]]:
    """Every folder's tables (benchmarks/*/tables.py, then the notebook's) by the folder that owns them."""
    if str(BENCHMARKS) not in sys.path:
        sys.path.insert(0, str(BENCHMARKS))
    owners = {}
    for path in sorted(BENCHMARKS.glob("*/tables.py")):
        owners[path.parent] = importlib.import_module(f"{path.parent.name}.tables").TABLES
    spec = importlib.util.spec_from_file_location("notebook_tables", NOTEBOOK_TABLES)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    owners[NOTEBOOK_TABLES.parent] = module.TABLES
    return owners


def all_tables() -> dict[str, Table]:
    """Every generated table by the name its markers use; a name two folders claim is an error."""
    tables: dict[str, Table] = {}
    for folder, owned in table_modules().items():
        for name in owned:
            if name in tables:
                raise KeyError(f"table {name!r} is defined twice (again in {folder})")
        tables.update(owned)
    return tables


TABLES = all_tables()
"""every generated table by the name its markers use"""

MARKER = re.compile(r"(<!-- table:(?P<name>[\w-]+) -->\n)(?P<body>.*?)(<!-- /table:(?P=name) -->)", re.S)


def render_document(text: str, root: Path) -> str:
    """`text` with each marked table replaced by its generated one; an unknown name is an error naming it."""
    def table(match: re.Match) -> str:
        name = match["name"]
        if name not in TABLES:
            raise KeyError(f"unknown table {name!r} (known: {', '.join(TABLES)})")
        return f"{match[1]}{TABLES[name](root)}\n{match[4]}"

    return MARKER.sub(table, text)


def update_tables(root: Path, check: bool = False) -> list[Path]:
    """Regenerate the tables of every document under `root` (or, with `check`, change nothing); the documents
    whose tables were (or would be) changed."""
    changed = []
    for relative in documents(root):
        path = root / relative
        if not path.exists():
            continue
        text = path.read_text()
        new = render_document(text, root)
        if new != text:
            changed.append(path)
            if not check:
                path.write_text(new)
    return changed


def study_commands(folder: Path) -> list[str]:
    """The commands a study's README gives for its CSVs: its indented lines that run a script."""
    readme = folder / "README.md"
    lines = readme.read_text().splitlines() if readme.is_file() else []
    return [line.strip() for line in lines if line.startswith("    .venv/bin/python ")]


def listing(root: Path) -> list[tuple[str, str, str, str]]:
    """Each table the README, docs/ or a study's README show: (table, documents, owning folder, the command that makes its CSV)."""
    shown: dict[str, list[str]] = {}
    for relative in documents(root):
        if relative.parts[0] != "notebook" and (root / relative).exists():
            for match in MARKER.finditer((root / relative).read_text()):
                shown.setdefault(match["name"], []).append(str(relative))
    rows = []
    for folder, owned in table_modules().items():
        for name in owned:
            if name in shown:
                rows.append((name, ", ".join(shown[name]), str(folder.relative_to(CHECKOUT)),
                             " ; ".join(study_commands(folder)) or "-"))
    return rows


def main(argv: list[str] | None = None) -> int:
    """Regenerate (or --check, or --list) the tables of the documents under --root."""
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--root", type=Path, default=CHECKOUT,
                        help="the checkout whose documents and CSVs to use (default: this one)")
    parser.add_argument("--check", action="store_true", help="change nothing; exit 2 when a table is out of date")
    parser.add_argument("--list", action="store_true", help="print each shown table's folder and command; change nothing")
    args = parser.parse_args(argv)
    if args.list:
        for row in listing(args.root):
            print(" | ".join(row))
        return 0
    changed = update_tables(args.root, check=args.check)
    for path in changed:
        print(f"{'out of date' if args.check else 'updated'}: {path}")
    return 2 if args.check and changed else 0


if __name__ == "__main__":
    sys.exit(main())
