#!/usr/bin/env bash
# Which frames reconstruct worst: reads the frames.csv that `tactfunc recon` writes and
# prints, per sensor and split (test by default),
#   1. the frames in five equal groups by the target's range (the difference's
#      peak-to-peak, normalised units), with each group's mean range, RMSE, PSNR
#      (against the noisy frames, and the noise-free ones when recorded) and depth;
#   2. the mean PSNR per tool (labelled frames only), worst first.
# Frames without a valid pixel (empty RMSE) are left out; exact fits (PSNR inf) count
# in the group sizes and RMSEs but not in the PSNR means.
#   usage: scripts/psnr_breakdown.sh RECON_DIR/frames.csv [train|test]
set -euo pipefail
export LC_ALL=C  # '.' decimals for sort -g and awk whatever the user's locale
csv=${1:?usage: $0 frames.csv [train|test]}
split=${2:-test}
case "$split" in
  train | test) ;;
  *) echo "$0: split must be train or test, got '$split'" >&2; exit 2 ;;
esac
test -r "$csv" || { echo "$0: cannot read $csv" >&2; exit 1; }
header='frame,sensor,split,tool,depth_m,target_range,source_range,rmse,psnr,psnr_clean,'
header+='psnr_zero,psnr_source_peak,contact,contact_score,contact_row,contact_col,'
header+='recon_contact_row,recon_contact_col'
[ "$(head -1 "$csv")" = "$header" ] ||
  { echo "$0: $csv: the header is not that of tactfunc recon's frames.csv" >&2; exit 1; }
# The columns below are split on plain commas; recon quotes a field holding a comma
# (a frame id or tool name), which this script does not parse: refuse such rows.
bad=$(awk -F, 'NR > 1 && NF != 18 { print NR; exit }' "$csv")
[ -z "$bad" ] ||
  { echo "$0: $csv:$bad: not 18 plain fields (a quoted id or tool?)" >&2; exit 1; }

for sensor in $(awk -F, 'NR > 1 { print $2 }' "$csv" | sort -u); do
  echo "$sensor ($split split): quintiles of the target's range"
  printf '%-9s %6s %10s %9s %9s %11s %10s\n' \
    quintile frames range rmse "psnr dB" "clean dB" "depth mm"
  awk -F, -v s="$sensor" -v sp="$split" '
      NR > 1 && $2 == s && $3 == sp && $8 != "" {
        print $6, $8, $9, ($5 == "" ? "nan" : $5), ($10 == "" ? "nan" : $10)
      }' "$csv" |
    sort -g |
    awk 'function finite(x) { return x != "inf" && x != "-inf" && x != "nan" }
         { r[NR] = $1; e[NR] = $2; p[NR] = $3; d[NR] = $4; c[NR] = $5 }
         END {
           for (q = 0; q < 5; ++q) {
             lo = int(q * NR / 5) + 1; hi = int((q + 1) * NR / 5); n = hi - lo + 1
             if (n <= 0) continue
             sr = se = sp = sd = sc = 0; np = nd = nc = 0
             for (i = lo; i <= hi; ++i) {
               sr += r[i]; se += e[i]
               if (finite(p[i])) { sp += p[i]; ++np }
               if (finite(d[i])) { sd += d[i]; ++nd }
               if (finite(c[i])) { sc += c[i]; ++nc }
             }
             psnr = "-"; clean = "-"; depth = "-"
             if (np > 0) psnr = sprintf("%.2f", sp / np)
             if (nc > 0) clean = sprintf("%.2f", sc / nc)
             if (nd > 0) depth = sprintf("%.2f", 1000 * sd / nd)
             printf "%-9d %6d %10.3f %9.4f %9s %11s %10s\n", q + 1, n, sr / n, se / n, psnr,
                    clean, depth
           }
         }'
  echo "$sensor ($split split): mean PSNR per tool, worst first"
  awk -F, -v s="$sensor" -v sp="$split" '
      NR > 1 && $2 == s && $3 == sp && $4 != "" && $9 != "" && $9 != "inf" {
        sum[$4] += $9; n[$4]++
      }
      END { for (t in sum) printf "%s\t%d\t%.2f\n", t, n[t], sum[t] / n[t] }' "$csv" |
    sort -t "$(printf '\t')" -k3,3 -g |
    awk -F '\t' '{ printf "%-14s %6d %9.2f\n", $1, $2, $3 }'
done
