#!/usr/bin/python3
"""Plots the service capacity curve written by scripts/bench-service.sh (OUT/capacity.csv).

    scripts/plot-capacity.py --out capacity.png [LABEL=]capacity.csv [[LABEL=]capacity.csv ...]

Left: server latency p50 and p99 (packet received -> pose handed to gRPC, ms, log scale) against
the number of concurrent real-time sessions, with the 2 ms goal; runs that fell behind are drawn
hollow. Right: the CPU that many real-time sessions need (server CPU per session-second of events
x sessions, cores; from `--capacity-speed max` runs this does not depend on what else the machine
runs) against the 2 cores, and the server's thread count. --cost-only draws the right panel
alone (for --capacity-speed max runs, whose latencies mean nothing). One line style per CSV (a build or
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
    for needed in ("sessions", "kept_up", "server_p50_us", "server_p99_us", "cpu_per_session_s",
                   "server_threads"):
        if needed not in rows[0]:
            raise ValueError(f"{path}: column '{needed}' is missing (not a capacity.csv?)")
    return sorted(rows, key=lambda row: row["sessions"])


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", required=True, help="PNG to write")
    parser.add_argument("curves", nargs="+", help="[LABEL=]capacity.csv")
    parser.add_argument("--title", default="evloc-localizer capacity: real-time 640x480 sessions")
    parser.add_argument("--cost-only", action="store_true", help="only the CPU and thread panel")
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

    if args.cost_only:
        figure, cost = plt.subplots(1, 1, figsize=(6, 4.2))
        latency = None
    else:
        figure, (latency, cost) = plt.subplots(1, 2, figsize=(11, 4.2))
    threads = cost.twinx()
    styles = ["-", "--", ":", "-."]
    for index, (label, rows) in enumerate(curves):
        style = styles[index % len(styles)]
        sessions = [row["sessions"] for row in rows]
        for key, name, color in (() if latency is None else
                                 (("server_p50_us", "p50", "tab:blue"),
                                  ("server_p99_us", "p99", "tab:red"))):
            values = [row[key] / 1000 for row in rows]
            latency.plot(sessions, values, style, color=color, label=f"{label} {name}")
            kept = [(s, v) for s, v, row in zip(sessions, values, rows) if row["kept_up"]]
            behind = [(s, v) for s, v, row in zip(sessions, values, rows) if not row["kept_up"]]
            if kept:
                latency.plot(*zip(*kept), "o", color=color)
            if behind:
                latency.plot(*zip(*behind), "o", color=color, markerfacecolor="none")
        cost.plot(sessions, [row["cpu_per_session_s"] * row["sessions"] for row in rows], style,
                  marker="o", color="tab:green", label=f"{label} CPU for real time (cores)")
        threads.plot(sessions, [row["server_threads"] for row in rows], style, marker="s",
                     color="tab:gray", label=f"{label} threads")
    if latency is not None:
        latency.axhline(2.0, color="black", linewidth=0.8, linestyle=":", label="goal p99 2 ms")
        latency.set_yscale("log")
        latency.set_xlabel("concurrent real-time sessions")
        latency.set_ylabel("server latency, ms (hollow: fell behind)")
        latency.legend(fontsize=7)
        latency.grid(True, which="both", alpha=0.3)
    cost.axhline(2.0, color="tab:green", linewidth=0.8, linestyle=":", label="2 cores")
    cost.set_xlabel("concurrent real-time sessions")
    cost.set_ylabel("CPU for real time, cores (green)")
    threads.set_ylabel("server threads (grey)")
    threads.set_ylim(bottom=0)
    cost.set_ylim(bottom=0)
    handles, labels = cost.get_legend_handles_labels()
    more_handles, more_labels = threads.get_legend_handles_labels()
    cost.legend(handles + more_handles, labels + more_labels, fontsize=7, loc="upper left")
    cost.grid(True, alpha=0.3)
    figure.suptitle(args.title)
    figure.tight_layout()
    figure.savefig(args.out, dpi=100)
    print(f"plot-capacity: wrote {args.out}")


if __name__ == "__main__":
    main()
