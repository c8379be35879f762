"""``fuelhm-bench schema``: print or write the JSON Schema of scenario files."""

from __future__ import annotations

import argparse
import json

from fuelhm_bench.io.outputs import write_text


def register(sub) -> None:
    p = sub.add_parser("schema", help="print or write the JSON Schema of scenario files (for editors)",
                       description="The JSON Schema (draft 2020-12) of scenario YAML files, generated from the "
                                   "scenario dataclasses. Point your editor's YAML language server at it, e.g. "
                                   "with '# yaml-language-server: $schema=scenario.schema.json' at the top of a file.")
    p.add_argument("--out", metavar="FILE", help="write the schema to FILE (.json) instead of printing it")
    p.add_argument("--force", action="store_true", help="overwrite FILE if it exists")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from fuelhm_bench.scenarios import scenario_json_schema

    text = json.dumps(scenario_json_schema(), indent=2) + "\n"
    if args.out is None:
        print(text, end="")
        return 0
    out = write_text(args.out, text, force=args.force, option="--out", kind="json", what="JSON Schema")
    print(f"wrote the scenario JSON Schema to {out}")
    return 0
