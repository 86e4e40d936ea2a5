#!/usr/bin/python3
"""Plots the chunked build's time and memory against the photo count (docs/mapper.md, "Chunked
build"; docs/benchmarks.md) from the results.tsv of scripts/bench-chunked-build.sh.

Usage: /usr/bin/python3 scripts/plot-chunked-build.py RESULTS.tsv --out PLOT.png
"""
import argparse
import csv

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("results", help="results.tsv of scripts/bench-chunked-build.sh")
    parser.add_argument("--out", required=True, help="the PNG to write")
    args = parser.parse_args()
    with open(args.results, newline="") as stream:
        rows = sorted(csv.DictReader(stream, delimiter="\t"), key=lambda row: int(row["photos"]))
    if not rows:
        raise SystemExit(f"{args.results}: no rows")
    photos = [int(row["photos"]) for row in rows]
    figure, (time_axis, memory_axis) = plt.subplots(1, 2, figsize=(10, 4))
    time_axis.plot(photos, [float(row["cpu_s"]) for row in rows], "o-", label="CPU (mapper + COLMAP)")
    time_axis.plot(photos, [float(row["wall_s"]) for row in rows], "s--", label="wall (loaded machine)")
    first = rows[0]
    for key, style in (("cpu_s", "k:"),):
        per_photo = float(first[key]) / int(first["photos"])
        time_axis.plot(photos, [per_photo * n for n in photos], style, label="linear from the smallest")
    time_axis.set_xlabel("photos")
    time_axis.set_ylabel("seconds")
    time_axis.set_title("time")
    time_axis.legend()
    memory_axis.plot(photos, [float(row["peak_tree_mb"]) for row in rows], "o-",
                     label="peak RSS, all processes")
    memory_axis.plot(photos, [float(row["peak_process_mb"]) for row in rows], "s--",
                     label="peak RSS, largest process")
    memory_axis.axhline(8192, color="r", linestyle=":", label="8 GB target")
    memory_axis.set_xlabel("photos")
    memory_axis.set_ylabel("MB")
    memory_axis.set_yscale("log")
    memory_axis.set_title("memory")
    memory_axis.legend()
    figure.tight_layout()
    figure.savefig(args.out, dpi=100)


if __name__ == "__main__":
    main()
