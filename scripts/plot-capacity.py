#!/usr/bin/python3
"""Plots the service capacity curve written by scripts/bench-service.sh (OUT/capacity.csv).

    scripts/plot-capacity.py --out capacity.png [LABEL=]capacity.csv [[LABEL=]capacity.csv ...]

Left: server latency p50 and p99 (packet received -> pose handed to gRPC, ms, log scale) against
the number of concurrent real-time sessions, with the 2 ms goal; runs that fell behind are drawn
hollow. Right: the server's CPU (cores) and its thread count. One line style per CSV (a build or
a configuration), so a before/after pair reads on one picture. Needs python3-matplotlib
(scripts/install-deps.sh); run it with /usr/bin/python3 (Debian's packages).
"""
import argparse
import csv
import sys


def read_curve(path):
    rows = []
    with open(path, newline="") as handle:
        for row in csv.DictReader(handle):
            rows.append({key: float(value) for key, value in row.items()})
    if not rows:
        raise ValueError(f"{path}: no rows (run scripts/bench-service.sh --capacity \"1 2 ...\")")
    for needed in ("sessions", "kept_up", "server_p50_us", "server_p99_us", "server_cores",
                   "server_threads"):
        if needed not in rows[0]:
            raise ValueError(f"{path}: column '{needed}' is missing (not a capacity.csv?)")
    return sorted(rows, key=lambda row: row["sessions"])


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", required=True, help="PNG to write")
    parser.add_argument("curves", nargs="+", help="[LABEL=]capacity.csv")
    parser.add_argument("--title", default="evloc-localizer capacity: real-time 640x480 sessions")
    args = parser.parse_args()
    try:
        import matplotlib
        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        sys.exit("plot-capacity: python3-matplotlib is missing (scripts/install-deps.sh), or run "
                 "with /usr/bin/python3")
    curves = []
    for spec in args.curves:
        label, _, path = spec.rpartition("=")
        try:
            curves.append((label or path, read_curve(path)))
        except (OSError, ValueError) as error:
            sys.exit(f"plot-capacity: {error}")

    figure, (latency, cost) = plt.subplots(1, 2, figsize=(11, 4.2))
    styles = ["-", "--", ":", "-."]
    for index, (label, rows) in enumerate(curves):
        style = styles[index % len(styles)]
        sessions = [row["sessions"] for row in rows]
        for key, name, color in (("server_p50_us", "p50", "tab:blue"),
                                 ("server_p99_us", "p99", "tab:red")):
            values = [row[key] / 1000 for row in rows]
            latency.plot(sessions, values, style, color=color, label=f"{label} {name}")
            kept = [(s, v) for s, v, row in zip(sessions, values, rows) if row["kept_up"]]
            behind = [(s, v) for s, v, row in zip(sessions, values, rows) if not row["kept_up"]]
            if kept:
                latency.plot(*zip(*kept), "o", color=color)
            if behind:
                latency.plot(*zip(*behind), "o", color=color, markerfacecolor="none")
        cost.plot(sessions, [row["server_cores"] for row in rows], style, marker="o",
                  color="tab:green", label=f"{label} CPU (cores)")
        cost.plot(sessions, [row["server_threads"] for row in rows], style, marker="s",
                  color="tab:gray", label=f"{label} threads")
    latency.axhline(2.0, color="black", linewidth=0.8, linestyle=":", label="goal p99 2 ms")
    latency.set_yscale("log")
    latency.set_xlabel("concurrent real-time sessions")
    latency.set_ylabel("server latency, ms (hollow: fell behind)")
    latency.legend(fontsize=7)
    latency.grid(True, which="both", alpha=0.3)
    cost.axhline(2.0, color="tab:green", linewidth=0.8, linestyle=":", label="2 cores")
    cost.set_xlabel("concurrent real-time sessions")
    cost.set_ylabel("server CPU (cores) / threads")
    cost.legend(fontsize=7)
    cost.grid(True, alpha=0.3)
    figure.suptitle(args.title)
    figure.tight_layout()
    figure.savefig(args.out, dpi=100)
    print(f"plot-capacity: wrote {args.out}")


if __name__ == "__main__":
    main()
