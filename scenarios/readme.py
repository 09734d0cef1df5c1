"""Copies a run's headline tables into README.md between its markers, so the figures the
README shows are always ones the command produced: ``python -m scenarios.readme RUN_DIR``."""

from __future__ import annotations

import sys
from pathlib import Path

from gridmap.atomic import write_atomically

BEGIN = "<!-- run tables: begin -->"
END = "<!-- run tables: end -->"


def splice(readme: str, report: str) -> str:
    if BEGIN not in readme or END not in readme:
        raise ValueError(f"README has no {BEGIN} ... {END} markers")
    body = report.split("\n", 1)[1].strip()          # drop the report's own title
    body = body.replace("\n## ", "\n#### ").replace("Figures: `fig_", "Figures (in the run "
                                                                    "folder): `fig_")
    head, rest = readme.split(BEGIN, 1)
    _, tail = rest.split(END, 1)
    return f"{head}{BEGIN}\n{body}\n{END}{tail}"


def main(argv: list[str] | None = None) -> int:
    args = sys.argv[1:] if argv is None else argv
    if len(args) != 1:
        print("usage: python -m scenarios.readme RUN_DIR", file=sys.stderr)
        return 2
    readme = Path(__file__).resolve().parents[1] / "README.md"
    report = (Path(args[0]) / "report.md").read_text()
    write_atomically(readme, splice(readme.read_text(), report))
    print(f"updated {readme}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
