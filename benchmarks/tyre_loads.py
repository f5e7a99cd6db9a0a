"""The tyres' vertical loads on each shipped route, against the Magic Formula's range of
validity F_z,max (``TyreParams.fzmax_n``, MF-Tyre's FZMAX; above it the formulas see F_z,max).

Each route is driven whole (the co-simulation with the default magic_formula car, sensor seed
``--seed``), one control period at a time; after each period the plugin's load of each wheel
(``tyre_states``: MuJoCo's solved contact force of the last physics step) is sampled. Printed
per route: the static load range (the first period at rest), the largest and the 99.9th
percentile of the sampled loads, and the share of samples above F_z,max.

    nice python benchmarks/tyre_loads.py                       # every library route
    nice python benchmarks/tyre_loads.py --routes rough_road highway
"""

from __future__ import annotations

import argparse

import numpy as np

from biso_cosim.cosim import CoSimulation
from biso_cosim.routes import route_names
from biso_cosim.vehicle.tyres import TYRES, tyre_states


def route_loads_n(route: str, seed: int) -> np.ndarray:
    """(periods, 4) wheel loads in N, sampled at the end of each control period."""
    sim = CoSimulation(route, estimators=["poisson"], seed=seed)
    rows = []
    while not sim.done:
        sim.step()
        rows.append(tyre_states(sim.vehicle.model, sim.vehicle.data)["load_n"])
    return np.asarray(rows)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--routes", nargs="+", default=route_names())
    ap.add_argument("--seed", type=int, default=0)
    args = ap.parse_args()
    top = TYRES.fzmax_n
    print(f"F_z,max = {top:g} N (F_z0 = {TYRES.fz0_n:g} N); loads sampled once per control period")
    print(f"{'route':<16} {'periods':>8} {'static N':>13} {'max N':>9} {'p99.9 N':>9} {'> F_z,max':>10}")
    for route in args.routes:
        loads = route_loads_n(route, args.seed)
        static = loads[0]
        print(f"{route:<16} {loads.shape[0]:>8d} {static.min():>6.0f}-{static.max():<6.0f} {loads.max():>9.0f} "
              f"{np.percentile(loads, 99.9):>9.0f} {100.0 * np.mean(loads > top):>9.3f}%")


if __name__ == "__main__":
    main()
