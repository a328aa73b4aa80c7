"""`irring bench …`: benchmarks that print measured figures.

Each benchmark is a module ``irring/cli/bench_<name>.py`` with ``register(parser)``,
imported only when that benchmark runs; the measurements live in ``irring/studies/``.
"""

from __future__ import annotations

import argparse

from ._common import add_subcommands, describe

# name → one-line help, in the order `irring bench --help` lists them
BENCHES = {
    "accuracy": "what accuracy costs in hardware time and compute time",
    "speed": "time per sweep of each stage, vs raw MuJoCo and vs the real ring",
    "effects": "cost of each sensor effect per sweep; an effect that is off costs ~0",
    "estimator": "iterative estimator vs θ = 0: range RMSE at steep incidence",
    "long": "the estimator's time and memory per reading as a sweep grows to 18,000 steps",
    "dynamics": "belt stretch, physics convergence, settle time vs angle error, mapping on "
                "the move",
    "rooms": "map scores on a set of rooms, scene effects vs an ideal sensor",
    "foldover": "fold-over from as close as the housing allows: wrong-branch readings, "
                "walls outside the room",
    "grazing": "end-point RMS per 10° of incidence vs θ = 0, walls up to ~70°",
    "sigma": "each reading's σ against its range error, per distance band and sensor model",
    "study": "how `irring study` scales: runs/s on 1 and N workers, memory",
    "render": "cost of the map pictures vs making the map; peak memory",
    "link": "corrupted IRSCN accepted under protocol v1's XOR vs v2's CRC-16; decode time",
}


def register(p: argparse.ArgumentParser) -> None:
    describe(p, "Benchmarks that measure and print figures on this machine.", raw=False)
    add_subcommands(p, "bench", "BENCH", BENCHES, lambda name: f"{__package__}.bench_{name}")
    p.set_defaults(func=lambda args: (p.print_help(), 2)[1])
