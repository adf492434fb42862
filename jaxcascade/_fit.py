"""`jaxcascade fit`: fit the cascade to one measured or simulated record."""

from __future__ import annotations

import json

import jax
import jax.numpy as jnp
import numpy as np

from ._data import read_record
from ._estimators import estimator
from ._metrics import fit_percent, nrmse
from ._model import CascadeParams, Orders
from ._simulate import simulate
from ._status import Status


def fit_record(u, y, orders: Orders, name: str = "robust", **settings):
    """Fit one record with the registered estimator `name`.

    Returns `(solution, error)` where `error` is the NRMSE of the free-run simulation
    of the estimate on the same record (inf when the estimate is inadmissible).
    """
    u = jnp.asarray(u)
    y = jnp.asarray(y, u.dtype)
    solution = jax.device_get(estimator(name)(u, y, orders, **settings))
    y_sim = np.asarray(
        simulate(CascadeParams.from_vector(solution.params.to_vector(), orders, check=False), u)
    )
    error = float(nrmse(np.asarray(y), y_sim))
    return solution, (error if np.isfinite(error) else float("inf"))


def run_fit(args) -> int:
    from ._cli import parse_orders

    orders = parse_orders(args.orders)
    estimator(args.estimator)  # unknown names fail here, before reading data
    record = read_record(
        args.data,
        args.input,
        args.output,
        time_column=args.time,
        decimate=args.decimate,
        scaling=args.scaling,
        orders=orders,
    )
    solution, error = fit_record(record.u, record.y, orders, args.estimator)
    status = Status(int(solution.status)).name
    estimates = solution.params.to_dict()
    result = {
        "estimator": args.estimator,
        "status": status,
        "estimates": estimates,
        "nrmse": error,
        "iterations": int(solution.iterations),
    }
    if args.scaling != "none":
        result["estimates_physical"] = record.scaling.params_to_physical(estimates)
        result["scaling"] = record.scaling.to_dict()
    if args.json:
        print(json.dumps(result))
        return 0
    print(f"{args.estimator} estimator: {status} after {result['iterations']} iterations")
    print(f"free-run NRMSE {error:.4g} (fit {fit_percent(error):.1f} %) on {len(record)} samples")
    for name, value in estimates.items():
        print(f"  {name:>4} = {value: .6f}")
    return 0


def add_parser(subparsers) -> None:
    from ._cli import add_record_arguments

    parser = subparsers.add_parser("fit", help="fit the cascade to a CSV or Parquet record")
    parser.add_argument("data", help="CSV or Parquet file")
    add_record_arguments(parser, scaling="none")
    parser.add_argument("--estimator", default="robust", help="literal or robust (default)")
    parser.add_argument("--json", action="store_true", help="print a JSON result")
    parser.set_defaults(func=run_fit)
