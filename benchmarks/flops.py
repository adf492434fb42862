"""Flops per fit of the benchmark workload, the float64 matmul rate and the FLOP floor.

    python benchmarks/flops.py [--n 4000] [--iterations 20] [--matmul-size 2048]

The counting lives in `jaxcascade._flops` (documented there, term by term).
"""

from __future__ import annotations

import argparse

import jax

from jaxcascade._benchmark._flops import floor_time, flops_per_fit, machine_rate, matmul_rates
from jaxcascade._system._examples import example


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--n", type=int, default=4000)
    parser.add_argument("--iterations", type=int, default=20)
    parser.add_argument("--example", type=int, default=1, choices=(1, 2))
    parser.add_argument("--matmul-size", type=int, default=2048)
    parser.add_argument("--repeats", type=int, default=3)
    args = parser.parse_args(argv)
    jax.config.update("jax_enable_x64", True)  # the floor is a float64 figure

    terms = flops_per_fit(example(args.example).orders, args.n, args.iterations)
    for name, value in terms.items():
        print(f"{name:26s} {value:>14,d}")
    rates = matmul_rates(args.matmul_size, args.repeats)
    for name, rate in rates.items():
        print(f"float64 matmul {args.matmul_size}^3 ({name}): {rate / 1e9:.1f} GFlop/s")
    name, rate = machine_rate(rates)
    seconds = floor_time(terms["total"], rate)
    print(f"floor ({name}): {seconds * 1e6:.1f} us per fit = {1 / seconds:.0f} fits/s")


if __name__ == "__main__":
    main()
