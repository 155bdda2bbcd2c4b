#!/usr/bin/env python3
"""Where the generator path's pose errors are: reads the per-contact rows that
`tactfunc eval-generator --contacts-csv FILE` writes and prints the mode's position and yaw
errors split by contact depth, by distance from the sensor's centre and by tool, the
contacts whose yaw is off by a large angle (mirrored or flipped modes), the mean error
vector (a systematic bias would show there), and per tool the position error along and
across the object's own x axis (a rod's long axis), over all contacts and the shallow ones,
beside the standard deviations the mode's Laplace component gives in those directions
(when the CSV has them): an error the posterior predicts is the frame's ambiguity, not a
miss. With `eval-generator --information` it also prints the Cramer-Rao bound in the same
splits (the floor any unbiased estimator has on those frames). docs/POSES.md quotes its
output.

Usage: python3 scripts/generator_errors.py CONTACTS.csv [MORE.csv ...] [--flip-deg 30]
       [--depth-edges-mm 6,10] [--radius-edges-mm 1.5,3]

Several CSVs (e.g. the runs of several seeds) are pooled into one set of contacts. When
the CSV has the posterior mean's columns it also prints the mean's position and yaw RMSE
(yaw modulo the tool's symmetry), the figures eval-generator prints for one run.

Pure Python (no third-party modules). Yaw statistics leave out tools of symmetry order 0
(the hemisphere), as eval-generator does.
"""
import argparse
import collections
import csv
import math
import sys


def rms(values):
    return math.sqrt(sum(v * v for v in values) / len(values)) if values else float("nan")


def median(values):
    s = sorted(values)
    return s[len(s) // 2] if s else float("nan")


def edges(text):
    try:
        return [float(v) for v in text.split(",") if v]
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected comma-separated millimetres, got '{text}'")


def bins(rows, key, cuts):
    bounds = [-math.inf] + cuts + [math.inf]
    for lo, hi in zip(bounds[:-1], bounds[1:]):
        chosen = [r for r in rows if lo <= key(r) < hi]
        label = (f"< {hi:g}" if lo == -math.inf else f">= {lo:g}" if hi == math.inf
                 else f"{lo:g}-{hi:g}")
        yield label, chosen


def folded_deg(delta_deg, n):
    """A yaw difference modulo the symmetry period 360 / n, in [-period/2, period/2)."""
    period = 360.0 / n
    return (delta_deg + period / 2) % period - period / 2


def optional(r, key):
    return float(r[key]) if r.get(key) not in (None, "", "nan") else float("nan")


def parse_row(r, index):
    row = {
        "id": index, "tool": r["tool"], "n": int(r["symmetry_order"]),
        "tx": float(r["truth_x_mm"]), "ty": float(r["truth_y_mm"]),
        "depth": float(r["truth_depth_mm"]),
        "tyaw": math.radians(float(r["truth_yaw_deg"])),
        "ex": float(r["mode_x_mm"]) - float(r["truth_x_mm"]),
        "ey": float(r["mode_y_mm"]) - float(r["truth_y_mm"]),
        "pos": float(r["position_error_mm"]),
        "yaw": optional(r, "yaw_error_deg"),
        "sdx": optional(r, "mode_sd_x_mm"), "sdy": optional(r, "mode_sd_y_mm"),
        "bx": optional(r, "bound_sd_along_mm"), "by": optional(r, "bound_sd_across_mm"),
        "byaw": optional(r, "bound_sd_yaw_deg"),
    }
    # The posterior mean's errors; NaN (absent, or no yaw for symmetry order 0) propagates.
    row["mpos"] = math.hypot(optional(r, "mean_x_mm") - row["tx"],
                             optional(r, "mean_y_mm") - row["ty"])
    row["myaw"] = (abs(folded_deg(optional(r, "mean_yaw_deg") - float(r["truth_yaw_deg"]),
                                  row["n"])) if row["n"] != 0 else float("nan"))
    return row


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("contacts", nargs="+",
                        help="eval-generator --contacts-csv output (several are pooled)")
    parser.add_argument("--flip-deg", type=float, default=30.0,
                        help="yaw errors at least this large count as flips (default 30)")
    parser.add_argument("--depth-edges-mm", type=edges, default=[6.0, 10.0])
    parser.add_argument("--radius-edges-mm", type=edges, default=[1.5, 3.0])
    args = parser.parse_args()
    required = ["tool", "symmetry_order", "truth_x_mm", "truth_y_mm", "truth_yaw_deg",
                "truth_depth_mm",
                "mode_x_mm", "mode_y_mm", "position_error_mm", "yaw_error_deg"]
    rows = []
    for path in args.contacts:
        try:
            with open(path, newline="") as f:
                reader = csv.DictReader(f)
                missing = [k for k in required if k not in (reader.fieldnames or [])]
                if missing:
                    sys.exit(f"generator_errors: {path}: missing column(s) "
                             f"{', '.join(missing)} (expected eval-generator --contacts-csv "
                             "output)")
                for line, r in enumerate(reader, start=2):
                    try:
                        rows.append(parse_row(r, len(rows)))
                    except ValueError as e:
                        sys.exit(f"generator_errors: {path}, line {line}: {e}")
        except OSError as e:
            sys.exit(f"generator_errors: cannot read {path}: {e.strerror}")
    if not rows:
        sys.exit(f"generator_errors: {', '.join(args.contacts)}: no contacts")

    with_bound = all(not math.isnan(r["bx"]) for r in rows)

    def bound_pos(chosen):
        # The floor on those contacts' position RMSE: sqrt of the mean bound trace.
        return rms([math.hypot(r["bx"], r["by"]) for r in chosen])

    def bound_text(chosen, yaws=None):
        if not with_bound:
            return ""
        text = f"; bound {bound_pos(chosen):.3f} mm"
        if yaws is not None:
            text += f", {rms([r['byaw'] for r in yaws]):.2f} deg"
        return text

    yawed = [r for r in rows if r["n"] != 0 and not math.isnan(r["yaw"])]
    flips = [r for r in yawed if r["yaw"] >= args.flip_deg]
    print(f"contacts: {len(rows)}; mode position RMSE {rms([r['pos'] for r in rows]):.3f} mm, "
          f"median {median([r['pos'] for r in rows]):.3f} mm; yaw RMSE "
          f"{rms([r['yaw'] for r in yawed]):.2f} deg over {len(yawed)} contacts with a yaw"
          + bound_text(rows, yawed))
    print(f"mean error vector (bias): x {sum(r['ex'] for r in rows) / len(rows):+.3f} mm, "
          f"y {sum(r['ey'] for r in rows) / len(rows):+.3f} mm")
    means = [r for r in rows if not math.isnan(r["mpos"])]
    if means:
        mean_yawed = [r for r in means if not math.isnan(r["myaw"])]
        print(f"posterior mean: position RMSE {rms([r['mpos'] for r in means]):.3f} mm over "
              f"{len(means)} contacts, yaw RMSE {rms([r['myaw'] for r in mean_yawed]):.2f} deg "
              f"over {len(mean_yawed)}")
    kept = [r for r in yawed if r["yaw"] < args.flip_deg]
    flip_ids = {r["id"] for r in flips}
    kept_ids = {r["id"] for r in kept}
    print(f"yaw off by >= {args.flip_deg:g} deg: {len(flips)} contacts "
          f"({dict(collections.Counter(r['tool'] for r in flips))}); without them: yaw RMSE "
          f"{rms([r['yaw'] for r in kept]):.2f} deg, position RMSE "
          f"{rms([r['pos'] for r in rows if r['id'] not in flip_ids]):.3f} mm")
    print("by true depth (mm):")
    for label, chosen in bins(rows, lambda r: r["depth"], args.depth_edges_mm):
        yaws = [r["yaw"] for r in chosen if r["id"] in kept_ids]
        print(f"  {label:>8}: {len(chosen):5d} contacts, position RMSE "
              f"{rms([r['pos'] for r in chosen]):.3f} mm, median "
              f"{median([r['pos'] for r in chosen]):.3f} mm, yaw RMSE without flips "
              f"{rms(yaws):.2f} deg"
              + bound_text(chosen, [r for r in chosen if r["id"] in kept_ids]))
    print("by distance of the truth from the sensor's centre (mm):")
    for label, chosen in bins(rows, lambda r: math.hypot(r["tx"], r["ty"]), args.radius_edges_mm):
        print(f"  {label:>8}: {len(chosen):5d} contacts, position RMSE "
              f"{rms([r['pos'] for r in chosen]):.3f} mm")
    print("by tool:")
    for tool in sorted({r["tool"] for r in rows}):
        chosen = [r for r in rows if r["tool"] == tool]
        yaws = [r["yaw"] for r in chosen if r["id"] in kept_ids]
        print(f"  {tool:>11}: {len(chosen):5d} contacts, position RMSE "
              f"{rms([r['pos'] for r in chosen]):.3f} mm, yaw RMSE without flips "
              f"{rms(yaws):.2f} deg, flips {sum(1 for r in flips if r['tool'] == tool)}"
              + bound_text(chosen, [r for r in chosen if r["id"] in kept_ids]))

    # The error in the truth's object frame: along its x axis and across it.
    def along(r):
        return r["ex"] * math.cos(r["tyaw"]) + r["ey"] * math.sin(r["tyaw"])

    def across(r):
        return -r["ex"] * math.sin(r["tyaw"]) + r["ey"] * math.cos(r["tyaw"])

    shallow_mm = args.depth_edges_mm[0] if args.depth_edges_mm else math.inf
    with_sd = all(not math.isnan(r["sdx"]) for r in rows)

    def predicted(chosen):
        # The RMS of the mode's Laplace standard deviations along / across, and the bound's.
        text = ""
        if with_sd:
            text += (f" (posterior sd {rms([r['sdx'] for r in chosen]):.3f} / "
                     f"{rms([r['sdy'] for r in chosen]):.3f})")
        if with_bound:
            text += (f" [bound {rms([r['bx'] for r in chosen]):.3f} / "
                     f"{rms([r['by'] for r in chosen]):.3f}]")
        return text

    print(f"position error RMSE along / across the object's x axis (mm), all contacts and "
          f"those below {shallow_mm:g} mm deep" +
          (", each beside the RMS of the mode's Laplace sd in those directions:" if with_sd
           else ":"))
    for tool in sorted({r["tool"] for r in rows}):
        chosen = [r for r in rows if r["tool"] == tool]
        shallow = [r for r in chosen if r["depth"] < shallow_mm]
        print(f"  {tool:>11}: {rms([along(r) for r in chosen]):.3f} / "
              f"{rms([across(r) for r in chosen]):.3f}{predicted(chosen)}; shallow "
              f"({len(shallow)}): {rms([along(r) for r in shallow]):.3f} / "
              f"{rms([across(r) for r in shallow]):.3f}{predicted(shallow)}")


if __name__ == "__main__":
    main()
