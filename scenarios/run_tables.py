"""Copies a run's headline tables into docs/main_job.md between its markers, so the figures
the page shows are always ones the command produced: ``python -m scenarios.run_tables RUN_DIR``
(``make run-tables``)."""

from __future__ import annotations

import sys
from pathlib import Path

from gridmap.atomic import write_atomically

BEGIN = "<!-- run tables: begin -->"
END = "<!-- run tables: end -->"


def splice(page: str, report: str) -> str:
    if BEGIN not in page or END not in page:
        raise ValueError(f"the page has no {BEGIN} ... {END} markers")
    body = report.split("\n", 1)[1].strip()          # drop the report's own title
    body = body.replace("\n## ", "\n### ").replace("Figures: `fig_", "Figures (in the run "
                                                                    "folder): `fig_")
    head, rest = page.split(BEGIN, 1)
    _, tail = rest.split(END, 1)
    return f"{head}{BEGIN}\n{body}\n{END}{tail}"


def main(argv: list[str] | None = None) -> int:
    args = sys.argv[1:] if argv is None else argv
    if len(args) != 1:
        print("usage: python -m scenarios.run_tables RUN_DIR", file=sys.stderr)
        return 2
    page = Path(__file__).resolve().parents[1] / "docs" / "main_job.md"
    report = (Path(args[0]) / "report.md").read_text()
    write_atomically(page, splice(page.read_text(), report))
    print(f"updated {page}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
