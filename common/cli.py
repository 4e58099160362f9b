"""The ``curriculum`` command: validate, bench (run, eval, compare and render come with later milestones)."""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from typing import Sequence

from common.errors import ConfigError

EXIT_BAD_INPUT = 2


def _validate(args: argparse.Namespace) -> int:
    from common.world_file import read_world_file

    for path in args.files:
        scenario = read_world_file(Path(path))
        print(f"ok: {path}: scenario {scenario.name!r}, {len(scenario.obstacles)} obstacles")
    return 0


def _bench(args: argparse.Namespace) -> int:
    from common.bench import run_benchmarks

    results = run_benchmarks(steps=args.steps)
    if args.json:
        print(json.dumps(results))
        return 0
    from rich.console import Console
    from rich.table import Table

    table = Table(title="curriculum bench")
    table.add_column("figure")
    table.add_column("value", justify="right")
    for key, value in results.items():
        table.add_row(key, "n/a (not installed)" if value is None else f"{value:,}" if isinstance(value, (int, float)) else str(value))
    Console().print(table)
    return 0


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="curriculum", description="Differential-drive navigation curricula, 2D to 3D.")
    commands = parser.add_subparsers(dest="command", required=True)

    validate = commands.add_parser("validate", help="check scenario or IR-SIM world YAML files")
    validate.add_argument("files", nargs="+", metavar="FILE")
    validate.set_defaults(handler=_validate)

    bench = commands.add_parser("bench", help="measure simulator speed against references in the same run")
    bench.add_argument("--json", action="store_true", help="print one JSON object")
    bench.add_argument("--steps", type=int, default=20_000, help="flatland steps to time (IR-SIM runs a tenth)")
    bench.set_defaults(handler=_bench)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point; bad input prints one line to stderr and exits with code 2."""
    args = build_parser().parse_args(argv)
    try:
        return args.handler(args)
    except ConfigError as error:
        print(f"error: {error}", file=sys.stderr)
        return EXIT_BAD_INPUT


if __name__ == "__main__":
    sys.exit(main())
