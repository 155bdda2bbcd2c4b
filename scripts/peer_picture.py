#!/usr/bin/env python3
# Copyright 2026 The tactfunc Authors.
"""Draws the ratios of one or more `scripts/bench_peer.sh` runs as an SVG bar chart.

Usage: scripts/peer_picture.py OUT.svg RUN.log [RUN.log ...]

Each RUN.log is the output of one bench_peer.sh run (its last JSON line is read). Per
workload (the fit's K steps, the whole fit, the meta-training step) and trunk width, one
bar per run: the median ratio PyTorch time / tactfunc time, with a whisker over its
range across rounds; a dashed line marks the product's aim at each width (the fit 3x at
width 64 and 2x above, the meta step 2x). Above 1, tactfunc is faster. Only the standard
library is used.
"""
import json
import sys

COLOURS = ["#4477aa", "#ee6677", "#228833", "#ccbb44", "#66ccee", "#aa3377"]
WORKLOADS = [("fit core", "the fit's K steps (like for like)"), ("full fit", "the whole fit"),
             ("meta step", "a meta-training step")]


def load(path):
    with open(path) as f:
        lines = [line for line in f if line.startswith('{"bench": "peer"')]
    if not lines:
        sys.exit(f"peer_picture: {path}: no bench_peer.sh summary line (its last JSON line)")
    run = json.loads(lines[-1])
    label = f"tactfunc {run.get('products', 'float')} / PyTorch {run.get('peer_products', 'float')}"
    return label, {(r["width"], r["workload"]): r for r in run["results"]}


def aim(workload, width):
    if workload == "meta step":
        return 2.0
    return 3.0 if width == 64 else 2.0


def main():
    if len(sys.argv) < 3:
        sys.exit(__doc__)
    out, runs = sys.argv[1], [load(p) for p in sys.argv[2:]]
    widths = sorted({w for _, results in runs for (w, _) in results})
    top = max(r["ratio_max"] for _, results in runs for r in results.values())
    top = max(top, 3.0) * 1.1
    panel_w, panel_h, left, bottom, header = 330, 260, 50, 40, 40
    width = left + len(WORKLOADS) * panel_w + 20
    height = header + panel_h + bottom + 22 * len(runs) + 24
    svg = [f'<svg xmlns="http://www.w3.org/2000/svg" width="{width}" height="{height}" '
           f'font-family="sans-serif" font-size="12">',
           f'<rect width="{width}" height="{height}" fill="white"/>']

    def y_of(v):
        return header + panel_h - v / top * panel_h

    for p, (workload, title) in enumerate(WORKLOADS):
        x0 = left + p * panel_w
        svg.append(f'<text x="{x0 + panel_w / 2}" y="{header - 18}" text-anchor="middle" '
                   f'font-weight="bold">{title}</text>')
        svg.append(f'<line x1="{x0}" y1="{header}" x2="{x0}" y2="{header + panel_h}" '
                   'stroke="black"/>')
        svg.append(f'<line x1="{x0}" y1="{header + panel_h}" x2="{x0 + panel_w - 20}" '
                   f'y2="{header + panel_h}" stroke="black"/>')
        for tick in range(0, int(top) + 1):
            y = y_of(tick)
            svg.append(f'<line x1="{x0 - 4}" y1="{y}" x2="{x0 + panel_w - 20}" y2="{y}" '
                       'stroke="#dddddd"/>')
            svg.append(f'<text x="{x0 - 6}" y="{y + 4}" text-anchor="end">{tick}x</text>')
        group = (panel_w - 40) / len(widths)
        bar = (group - 12) / len(runs)
        for g, w in enumerate(widths):
            gx = x0 + 10 + g * group
            for i, (_, results) in enumerate(runs):
                r = results.get((w, workload))
                if r is None:
                    continue
                bx = gx + i * bar
                y_top = y_of(r["ratio_median"])
                svg.append(f'<rect x="{bx:.1f}" y="{y_top:.1f}" width="{bar - 2:.1f}" '
                           f'height="{y_of(0) - y_top:.1f}" fill="{COLOURS[i % len(COLOURS)]}"/>')
                cx = bx + (bar - 2) / 2
                svg.append(f'<line x1="{cx:.1f}" y1="{y_of(r["ratio_min"]):.1f}" x2="{cx:.1f}" '
                           f'y2="{y_of(r["ratio_max"]):.1f}" stroke="black"/>')
            target = aim(workload, w)  # drawn over the bars
            svg.append(f'<line x1="{gx - 3}" y1="{y_of(target)}" x2="{gx + group - 9}" '
                       f'y2="{y_of(target)}" stroke="black" stroke-width="2" '
                       'stroke-dasharray="6,3"/>')
            svg.append(f'<text x="{gx + (group - 12) / 2}" y="{header + panel_h + 16}" '
                       f'text-anchor="middle">width {w}</text>')
    for i, (label, _) in enumerate(runs):
        y = header + panel_h + bottom + 22 * i
        svg.append(f'<rect x="{left}" y="{y}" width="14" height="14" '
                   f'fill="{COLOURS[i % len(COLOURS)]}"/>')
        svg.append(f'<text x="{left + 20}" y="{y + 12}">{label}</text>')
    y = header + panel_h + bottom + 22 * len(runs) + 4
    svg.append(f'<text x="{left}" y="{y}">bars: PyTorch time / tactfunc time (above 1x tactfunc '
               'is faster), median over rounds, whiskers the range; dashed: the aim</text>')
    svg.append("</svg>")
    with open(out, "w") as f:
        f.write("\n".join(svg) + "\n")
    print(f"peer_picture: wrote {out}")


if __name__ == "__main__":
    main()
