"""``fuelhm-bench validate``: check scenario files (or shipped scenarios) against the schema."""

from __future__ import annotations

import argparse

from fuelhm_bench.errors import FuelHMError, ParameterError


def register(sub) -> None:
    p = sub.add_parser("validate", help="validate scenario YAML files against the scenario schema",
                       description="Load and validate each scenario file (or shipped scenario name). Prints "
                                   "'OK' with the scenario id, or every problem as FILE:LINE: FIELD must be "
                                   "ALLOWED. Got GIVEN instead. Exit status 2 if any file is invalid (bad input, as every "
                                   "command).")
    p.add_argument("files", nargs="*", metavar="FILE", help="scenario YAML files, or shipped names like all_modes")
    p.add_argument("--shipped", action="store_true", help="also validate every shipped scenario")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from fuelhm_bench.scenarios import list_scenarios, load_scenario

    targets = list(args.files) + (list(list_scenarios()) if args.shipped else [])
    if not targets:
        raise ParameterError("validate needs at least one FILE or --shipped (see 'fuelhm-bench validate --help').")
    n_bad = 0
    for target in targets:
        try:
            scenario = load_scenario(target)
        except FuelHMError as exc:
            n_bad += 1
            print(f"INVALID {target}")
            for line in str(exc).splitlines():
                print(f"  {line}")
        else:
            print(f"OK      {target} ({scenario.id})")
    if len(targets) > 1 or n_bad:
        print(f"{len(targets) - n_bad} valid, {n_bad} invalid")
    return 2 if n_bad else 0  # invalid input: the status of every command's bad input
