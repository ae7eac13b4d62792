#!/usr/bin/env bash
# Usage: parameters-at-noise.sh BIN_DIR OUT SEED...   (from the checkout's root)
# GEOMETRIC_SCALE=10 multiplies the truth's joint-frame and zero-offset magnitudes (a 3 mm arm instead of 0.4 mm).
# The 7-joint tracker case in simulation: paper_iiwa's arm and tracker (reflector on the flange axis, position only),
# one campaign of a 216-point grid (144 train, 72 validation, by a fixed shuffle) and 20 uniform test points.
set -eu
B=$1; OUT=$2; shift 2
mkdir -p $OUT
for seed in "$@"; do
  S=$OUT/s$seed; mkdir -p $S
  python3 - "$seed" "${GEOMETRIC_SCALE:-1}" > $S/scenario.toml <<'PY'
import sys
seed, k = sys.argv[1], float(sys.argv[2])
t = open("scenarios/paper_iiwa.toml").read()
t = t.split("[evaluation]")[0]
t = t.replace("seed = 2019", f"seed = {seed}", 1)
if k != 1:
    for key, value in [("frame_translation_m", "2e-4"), ("frame_rotation_rad", "5e-4"), ("joint_zero_rad", "7e-4")]:
        assert f"{key} = {value}" in t, key
        t = t.replace(f"{key} = {value}", f"{key} = {float(value) * k:e}", 1)
head, region = t.split("[[regions]]", 1)
grid = region.replace('name = "paper"', 'name = "grid"').replace("points = 2335", "points = 216").replace('layout = "uniform"', 'layout = "grid"')
test = region.replace('name = "paper"', 'name = "test"').replace("points = 2335", "points = 20")
print(head + "[[regions]]" + grid + "\n[[regions]]" + test)
PY
  [ -f $S/campaign/measurements.csv ] || $B/campaign $S/scenario.toml --out $S/campaign > $S/campaign.log 2>&1
  python3 - $S/campaign/measurements.csv $S/split.csv <<'PY'
import csv, random, sys
rows = list(csv.reader(open(sys.argv[1])))
h = rows[0]; r = h.index("region")
grid = [i for i in range(1, len(rows)) if rows[i][r] == "grid"]
random.Random(26).shuffle(grid)
train = set(grid[:144])
w = csv.writer(open(sys.argv[2], "w", newline=""))
w.writerow(h + ["split"])
for i in range(1, len(rows)):
    s = "test" if rows[i][r] == "test" else ("train" if i in train else "val")
    w.writerow(rows[i] + [s])
PY
  for m in nominal kinematic elastic hybrid hybrid-kinematic; do
    $B/calibrate --data $S/split.csv --truth $S/campaign/truth.csv --payload-kg 0.4 --method $m --out $S/cal_$m > $S/cal_$m.log 2>&1 || echo "seed $seed $m failed: $(tail -1 $S/cal_$m.log)"
  done
done
python3 - $OUT "$@" <<'PY'
import json, sys
out = sys.argv[1]; seeds = sys.argv[2:]
ms = ["nominal", "kinematic", "elastic", "hybrid", "hybrid-kinematic"]
print("seed | " + " | ".join(ms) + "   (held-out mean / RMS mm on the 20 test points)")
acc = {m: [] for m in ms}
for s in seeds:
    cells = []
    for m in ms:
        try:
            r = json.load(open(f"{out}/s{s}/cal_{m}/report.json"))
            a = r["test"]["after"]; acc[m].append(a["mean_mm"])
            cells.append(f"{a['mean_mm']:.4f}/{a['rms_mm']:.4f}")
        except Exception as e:
            cells.append("fail")
    print(s + " | " + " | ".join(cells))
print("mean | " + " | ".join(f"{sum(v)/len(v):.4f}" if v else "-" for v in acc.values()))
for s in seeds:
    for m in ["kinematic", "elastic"]:
        try:
            r = json.load(open(f"{out}/s{s}/cal_{m}/report.json"))
            f = r
            und = [u["parameter"] for u in f.get("undetermined", [])]
            print(f"seed {s} {m}: kept {len(f['kept_parameters'])}, noise {f.get('noise_mm')} mm ({f.get('noise_source')}), undetermined {und}")
        except Exception as e:
            print(s, m, "?", e)
PY
