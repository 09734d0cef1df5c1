"""Draw a session's world of a scenario to a PNG:

    python -m sim.render SCENARIO.yaml --session W2 --out w2.png
"""

from __future__ import annotations

import argparse
import sys

from .drawing import render_world
from .scenario import ScenarioError, load_scenario


def main(argv=None) -> int:
    p = argparse.ArgumentParser(prog="python -m sim.render",
                                description="Draw a session's world of a scenario to a PNG.")
    p.add_argument("scenario", help="scenario YAML file")
    p.add_argument("--session", default="0", help="session name or index (default: the first)")
    p.add_argument("--out", default="world.png", help="output PNG (default: world.png)")
    p.add_argument("--time", type=float, default=0.0, help="draw the state at this time [s]")
    p.add_argument("--seed", type=int, default=None, help="seed (default: the scenario's)")
    args = p.parse_args(argv)
    session = int(args.session) if args.session.isdigit() else args.session
    try:
        scenario = load_scenario(args.scenario)
        out = render_world(scenario, session, args.out, seed=args.seed, time=args.time)
    except ScenarioError as e:
        print(f"error: {e}", file=sys.stderr)
        return 2
    print(f"wrote {out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
