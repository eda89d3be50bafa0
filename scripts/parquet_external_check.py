#!/usr/bin/env python3
"""Read a survey's survey.parquet with pyarrow (a reader other than the Rust writer) and check
it holds what survey.csv holds: the same columns in the same order, the same rows, every value
equal (numbers exactly, empty CSV cells as nulls, booleans as true/false).

    python3 -m venv /tmp/pq && /tmp/pq/bin/pip install pyarrow
    /tmp/pq/bin/python scripts/parquet_external_check.py out/survey/survey

Exit status 0 when they agree, 1 (with the first differences) when not.
"""

import csv
import math
import sys
from pathlib import Path

import pyarrow.parquet as pq


def same(cell: str, value) -> bool:
    if value is None:
        return cell == ""
    if isinstance(value, bool):
        return cell == ("true" if value else "false")
    if isinstance(value, (int, float)):
        try:
            number = float(cell)
        except ValueError:
            return False
        return number == value or (math.isnan(number) and math.isnan(value))
    return cell == str(value)


def main(folder: Path) -> int:
    table = pq.read_table(folder / "survey.parquet")
    with open(folder / "survey.csv", newline="") as f:
        rows = list(csv.reader(f))
    header, body = rows[0], rows[1:]
    problems = []
    if table.column_names != header:
        problems.append(f"columns differ: {table.column_names} vs {header}")
    if table.num_rows != len(body):
        problems.append(f"{table.num_rows} Parquet rows, {len(body)} CSV rows")
    if not problems:
        columns = [table.column(name).to_pylist() for name in header]
        for r, row in enumerate(body):
            for c, name in enumerate(header):
                if not same(row[c], columns[c][r]):
                    problems.append(f"row {r + 1}, {name}: CSV {row[c]!r}, Parquet {columns[c][r]!r}")
    for p in problems[:20]:
        print(p, file=sys.stderr)
    if problems:
        return 1
    types = sorted({str(t) for t in table.schema.types})
    print(f"{folder}: {table.num_rows} rows x {table.num_columns} columns agree ({', '.join(types)})")
    return 0


if __name__ == "__main__":
    sys.exit(main(Path(sys.argv[1] if len(sys.argv) > 1 else "out/survey")))
