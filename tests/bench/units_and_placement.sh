#!/bin/bash
# Does an answer depend on the clouds' units or on where they lie? 40 unseen object pairs
# (`rpsr data pairs --protocol objects --split unseen --count 40 --seed 1`), registered as they
# are, scaled by 1/1024 and by 1024 (exact in floating point), and moved by 1,000 along each axis;
# trees to depth 6 in every case (rpsr eval's own default; the object protocol's depth). Prints, per placement and mode, rpsr eval's summary row: rotation RMSE / MAE / median
# (degrees: comparable across placements), translation RMSE / median (the clouds' units:
# scaled with them, and for the moved clouds also the rotation error times ~1,700), recall (its
# absolute thresholds only mean something at unit scale), and ms a pair; then the mean confidence.
# Usage: tests/bench/units_and_placement.sh [RPSR_BINARY] [WORK_DIR]
set -euo pipefail
rpsr=${1:-build/client/cli/rpsr}
work=${2:-$(mktemp -d)}
mkdir -p "$work"
"$rpsr" data pairs --protocol objects --split unseen --count 40 --seed 1 --format xyz \
  --output "$work/unit" > /dev/null 2>&1
python3 - "$work" <<'PY'
import csv, os, sys
work = sys.argv[1]
rows = list(csv.reader(open(f"{work}/unit/manifest.csv")))[1:]
def load(path):
    return [list(map(float, l.split())) for l in open(path) if l.strip()]
for scale, offset, tag in [(1.0, 0.0, "unit"), (1 / 1024, 0.0, "scale_1_1024"),
                           (1024.0, 0.0, "scale_1024"), (1.0, 1000.0, "offset_1000")]:
    os.makedirs(f"{work}/{tag}_clouds", exist_ok=True)
    out = [["source", "target", "gt"]]
    for i, (s, t, gt) in enumerate(rows):
        g = list(map(float, gt.split()))
        R = [[g[4 * r + c] for c in range(3)] for r in range(3)]
        for r in range(3):  # t' = scale t + o - R o for both clouds mapped p -> scale p + o
            g[4 * r + 3] = scale * g[4 * r + 3] + offset - sum(R[r][c] * offset for c in range(3))
        names = []
        for which, path in (("s", s), ("t", t)):
            name = f"{work}/{tag}_clouds/{i}_{which}.xyz"
            with open(name, "w") as f:
                for p in load(f"{work}/unit/{path}"):
                    f.write("%.17g %.17g %.17g\n" % tuple(x * scale + offset for x in p))
            names.append(name)
        out.append(names + [" ".join("%.17g" % x for x in g)])
    csv.writer(open(f"{work}/{tag}.csv", "w")).writerows(out)
PY
for mode in refine net+refine; do
  for tag in unit scale_1_1024 scale_1024 offset_1000; do
    "$rpsr" eval --manifest "$work/$tag.csv" --tree_depth 6 --mode "$mode" \
      --output "$work/${tag}_$mode.csv" > "$work/${tag}_$mode.log" 2>&1
    row=$(tail -1 "$work/${tag}_$mode.log" | awk '{$1=""; print}')
    conf=$(python3 -c "import csv,sys; r=list(csv.DictReader(open(sys.argv[1]))); \
print('%.3f' % (sum(float(x['confidence']) for x in r) / len(r)))" "$work/${tag}_$mode.csv")
    printf '%-11s %-13s %s | mean confidence %s\n' "$mode" "$tag" "$row" "$conf"
  done
done
