#!/usr/bin/env python3
"""How far the generator's rendering is from ranking its wrong modes right.

Reads the contacts CSV of `tactfunc eval-generator --diagnose --information
--contacts-csv C.csv` and, for every contact whose heaviest mode is at least --min-yaw
degrees off (modulo symmetry; tools with an observable yaw), compares three whole-frame
objectives (nats at the trunk's pixel sigma, every valid pixel; docs/POSES.md, "How far
the renderer is from ranking them"):

  * the generator's preference for the mode: its objective at the truth minus at the mode
    (> 0: it ranks the mode first);
  * the generator's excess at the truth: its objective at the truth minus the trunk's own
    best latent's (Ceres to convergence), the error of its rendering beyond the trunk's;
  * the margin the trunk keeps: trunk_llr_truth_over_mode, by how much the trunk's best
    renderings of the simulator's noise-free frames at the truth and at the mode tell
    them apart (> 0: the truth first).

A renderer ranks the truth first once its excess falls well below that margin; the
ratio of the two says how many times less error that takes.

  python3 scripts/wrong_mode_margins.py C.csv [--min-yaw 30]
"""
import argparse
import csv
import math
import statistics
import sys


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("csv", help="contacts CSV of eval-generator --diagnose --information")
    parser.add_argument("--min-yaw", type=float, default=30.0,
                        help="yaw error (deg) from which a mode counts as flipped (default 30)")
    args = parser.parse_args()
    needed = ["contact", "tool", "symmetry_order", "truth_depth_mm", "yaw_error_deg",
              "trunk_llr_truth_over_mode", "whole_frame_truth_cost", "whole_frame_mode_cost",
              "whole_frame_trunk_best_cost"]
    with open(args.csv, newline="") as f:
        reader = csv.DictReader(f)
        missing = [n for n in needed if n not in (reader.fieldnames or [])]
        if missing:
            sys.exit(f"{args.csv}: no field {', '.join(missing)} (expected the contacts CSV of "
                     "`tactfunc eval-generator --diagnose --information --contacts-csv`)")
        rows = list(reader)
    flips = []
    for line, r in enumerate(rows, start=2):
        if r["symmetry_order"] == "0" or float(r["yaw_error_deg"]) < args.min_yaw:
            continue
        values = [float(r[n]) for n in needed[5:]]
        if any(math.isnan(v) for v in values):
            sys.exit(f"{args.csv}:{line}: a flipped mode without the --diagnose and "
                     "--information columns (run eval-generator with both)")
        llr, truth, mode, best = values
        flips.append((int(r["contact"]), r["tool"], float(r["truth_depth_mm"]),
                      float(r["yaw_error_deg"]), truth - mode, truth - best, llr))
    print(f"{len(flips)} of {len(rows)} contacts have their heaviest mode {args.min_yaw:g} deg "
          "or more off")
    if not flips:
        return
    print("contact tool        depth_mm yaw_err_deg prefers_mode_nats excess_at_truth_nats "
          "trunk_margin_nats excess/margin")
    for k, tool, depth, yaw, prefers, excess, llr in flips:
        ratio = excess / llr if llr > 0 else math.inf
        print(f"{k:7d} {tool:11s} {depth:8.2f} {yaw:11.1f} {prefers:17.1f} {excess:20.1f} "
              f"{llr:17.1f} {ratio:13.1f}")
    med = statistics.median
    kept = [f for f in flips if f[6] > 0]
    print(f"median: the generator prefers the mode by {med(f[4] for f in flips):.1f} nats "
          f"(it ranks the mode first in {sum(f[4] > 0 for f in flips)} of {len(flips)}); its "
          f"excess at the truth {med(f[5] for f in flips):.1f} nats; the trunk's margin "
          f"{med(f[6] for f in flips):.1f} nats (the truth first in {len(kept)})")
    if kept:
        ratios = sorted(f[5] / f[6] for f in kept)
        print(f"excess over margin where the trunk ranks the truth first: median "
              f"{med(ratios):.1f}, range {ratios[0]:.1f}-{ratios[-1]:.1f}")


if __name__ == "__main__":
    main()
