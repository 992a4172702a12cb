#!/usr/bin/env bash
# Regenerate every number and figure of docs/REPRODUCTION.md (about 18 minutes on 2 cores).
# Usage: bash docs/reproduce.sh [OUTDIR]   (needs: pip install '.[report]')
# Two full-scale trials: "default" (seed 1, the slowly varying current) and "tidal" (seed 1,
# a constant 0.25 m/s current: 0.20 north, 0.15 east). The tables are printed at the end,
# in the page's markdown, from the JSON the commands wrote.
set -euo pipefail
out="${1:-/tmp/emlogd-trial}"
emlogd() { command "${EMLOGD:-emlogd}" "$@"; }
python="${PYTHON:-python3}"   # with PyYAML (the Python emlogd is installed in)
scale="${SCALE:-1}"           # the page uses full scale; SCALE=0.1 for a quick check
names=(1-transit 2-figure8 3-straight 4-circles 5-return)
declare -A lag=([emlog1]=3.3 [emlog2]=0.5)   # the true latencies plus the serial transmission

# progress: every stage line says the time since the start; once the first trial is done
# the script says when it expects the second trial to end (it does the same work)
SECONDS=0
stage() { printf '== [%d:%02d] %s\n' $((SECONDS / 60)) $((SECONDS % 60)) "$*"; }
for trial in default tidal; do
  dir="$out/$trial"
  stage "$trial: simulating the trial (scale $scale)"
  if [ "$trial" = default ]; then
    time emlogd simulate "$dir" --seed 1 --scale "$scale"
  else
    time emlogd simulate "$dir" --seed 1 --scale "$scale" --current 0.2,0.15
  fi
  caps=()
  for n in "${names[@]}"; do caps+=("$dir/$n.cap"); done
  json="$dir/json"
  mkdir -p "$json"

  stage "$trial: cross-validation against the DVL (the paper's tables)"
  for cur in paper current; do
    flag=(); [ "$cur" = current ] && flag=(--current)
    time emlogd crossval "${caps[@]}" --uut emlog1 --ref dvl --lag 3.3 "${flag[@]}" --json \
      > "$json/cv-emlog1-$cur.json"
    emlogd crossval "${caps[@]}" --uut emlog2 --ref dvl --lag 0.5 "${flag[@]}" --json \
      > "$json/cv-emlog2-$cur.json"
  done
  emlogd crossval "${caps[@]}" --uut emlog1 --ref emlog2 --ref-field speed --json \
    > "$json/cv-emlog1-emlog2.json"

  stage "$trial: LS-EM3 trained on each trajectory, scored against the truth on every one"
  for uut in emlog1 emlog2; do
    for train in "${names[@]}"; do
      for cur in paper current; do
        flag=(); [ "$cur" = current ] && flag=(--current)
        p="$json/params-$uut-$train-$cur.yaml"
        emlogd calibrate "$dir/$train.cap" --uut "$uut" --ref dvl --lag "${lag[$uut]}" \
          "${flag[@]}" --save "$p" --json > "$json/cal-$uut-$train-$cur.json"
        emlogd evaluate "${caps[@]}" --params "$p" --truth "$dir" --json \
          > "$json/eval-$uut-$train-$cur.json"
      done
    done
  done

  stage "$trial: the daemon's online calibration (replay), scored against the truth"
  for cur in paper current; do
    c=false; [ "$cur" = current ] && c=true
    cat > "$dir/replay-$cur.yaml" <<EOF
ports:
  - {name: emlog1, url: /dev/null, protocol: nmea0183, role: uut}
  - {name: emlog2, url: /dev/null, protocol: nmea0183, role: uut}
  - {name: dvl, url: /dev/null, protocol: pd6, role: reference}
calibration:
  - {uut: emlog1, reference: dvl, lag: 3.3, current: $c}
  - {uut: emlog2, reference: dvl, lag: 0.5, current: $c, talker: VM}
EOF
    time emlogd replay "${caps[@]}" --config "$dir/replay-$cur.yaml" --truth "$dir" --json \
      > "$json/replay-$cur.json"
    # from an empty state with the automatic lag: transit and figure-8 first, then the rest
    # scored (the calibration the figure-8 left, still learning)
    sed 's/lag: [0-9.]*, //' "$dir/replay-$cur.yaml" > "$dir/replay-auto-$cur.yaml"
    rm -f "$dir/state-$cur.yaml" "$dir/state-$cur.yaml.bak"
    emlogd replay "${caps[@]:0:2}" --config "$dir/replay-auto-$cur.yaml" \
      --state "$dir/state-$cur.yaml" --json > /dev/null
    emlogd replay "${caps[@]:2:3}" --config "$dir/replay-auto-$cur.yaml" \
      --state "$dir/state-$cur.yaml" --truth "$dir" --json > "$json/replay-after-$cur.json"
  done
  if [ "$trial" = default ]; then
    per=$SECONDS
    stage "default trial done in $((per / 60)) min $((per % 60)) s; the tidal trial takes" \
      "about as long: done about $((2 * per / 60 + 1)) min from the start, then the checks"
  fi
done

stage "identifiability of the straight run (default trial)"
emlogd calibrate "$out/default/3-straight.cap" --uut emlog1 --ref dvl --lag 3.3
stage "the automatic lag of EMlog1 on the figure-8, with the current states (default trial)"
emlogd calibrate "$out/default/2-figure8.cap" --uut emlog1 --ref dvl --current | sed -n 2p
stage "KF-EM3 on the figure-8 (default trial)"
emlogd calibrate "$out/default/2-figure8.cap" --uut emlog1 --ref dvl --method kf
stage "KF-EM3 with the current states on the figure-8: the default reading noise, then each log's true one (default trial)"
emlogd calibrate "$out/default/2-figure8.cap" --uut emlog1 --ref dvl --lag 3.3 --method kf \
  --current | grep NIS
emlogd calibrate "$out/default/2-figure8.cap" --uut emlog1 --ref dvl --lag 3.3 --method kf \
  --current --r-raw 0.03 | grep NIS
emlogd calibrate "$out/default/2-figure8.cap" --uut emlog2 --ref dvl --lag 0.5 --method kf \
  --current --r-raw 0.05 | grep NIS
default_caps=()
for n in "${names[@]}"; do default_caps+=("$out/default/$n.cap"); done
emlogd report "${default_caps[@]}" --uut emlog1 --ref dvl --out "$out/figures"

stage "tables (markdown)"
"$python" - "$out" <<'EOF'
import json, math, sys
from pathlib import Path

out = Path(sys.argv[1])
names = ["1-transit", "2-figure8", "3-straight", "4-circles", "5-return"]
short = {"1-transit": "1", "2-figure8": "2", "3-straight": "3", "4-circles": "4", "5-return": "5"}


def f(x):
    return "–" if x is None or not math.isfinite(x) else f"{x:.3f}"


def lag_txt(x):
    return "not found" if x is None else f"{x:.2f}"


def pct(x):
    return "–" if x is None else f"{x:.0f}%"


def imo(rows, which):
    # the IMO A.824(19) verdict pooled over rows (calib.metrics.imo_verdict per capture):
    # the fraction of samples within max(2 % of the speed, 0.2 kn); meets at >= 95 %
    v = [r["imo"][which] for r in rows if r.get("imo")]
    n = sum(x["n"] for x in v)
    if not n:
        return "–"
    frac = sum(x["within"] for x in v) / n
    return f"{100 * frac:.0f} % {'meets' if frac >= 0.95 else 'fails'}"
def pooled(rows, key):
    n = sum(r["n_samples"] for r in rows)
    return math.sqrt(sum(r["n_samples"] * r[key] ** 2 for r in rows) / n) if n else math.nan


for trial in ("default", "tidal"):
    j = out / trial / "json"
    truth = out / trial / "truth.yaml"
    print(f"\n### {trial}: the trajectories\n")
    import yaml

    doc = yaml.safe_load(truth.read_text())
    print("| trajectory | duration | mean STW | max current | bottom lock | raw vs truth EMlog1 / EMlog2 | floor EMlog1 / EMlog2 | IMO raw EMlog1 / EMlog2 |")
    print("|---|---|---|---|---|---|---|---|")
    ev = json.loads((j / "eval-emlog1-2-figure8-paper.json").read_text())["captures"]
    ev2 = json.loads((j / "eval-emlog2-2-figure8-paper.json").read_text())["captures"]
    for t, a, b in zip(doc["trajectories"], ev, ev2):
        print(
            f"| {t['file'][:-4]} | {t['duration_s'] / 60:.0f} min | {t['mean_stw_mps']:.2f} m/s "
            f"| {t['max_current_mps']:.2f} m/s | {100 * t['bottom_lock_fraction']:.0f} % "
            f"| {f(a['truth']['rmse_raw'])} / {f(b['truth']['rmse_raw'])} "
            f"| {f(a['truth']['rmse_floor'])} / {f(b['truth']['rmse_floor'])} "
            f"| {imo([a['truth']], 'raw')} / {imo([b['truth']], 'raw')} |"
        )
    for uut in ("emlog1", "emlog2"):
        print(f"\n### {trial}: {uut}, LS-EM3 trained on one trajectory, RMSE against the truth (m/s)\n")
        print("| trained on | method | " + " | ".join(short[n] for n in names) + " | out-of-sample pooled | IMO out-of-sample | m, b | current N, E |")
        print("|---|---|" + "---|" * (len(names) + 4))
        for train in names:
            for cur in ("paper", "current"):
                e = json.loads((j / f"eval-{uut}-{train}-{cur}.json").read_text())
                c = json.loads((j / f"cal-{uut}-{train}-{cur}.json").read_text())
                rows = {Path(r["capture"]).stem: r["truth"] for r in e["captures"]}
                cells = [
                    f(rows[n]["rmse_corrected"]) + ("*" if n == train else "") for n in names
                ]
                oos = [rows[n] for n in names if n != train]
                p = c["params"]
                cu = c.get("current")
                cur_txt = "–" if not cu else f"{cu['north_mps']:+.2f}, {cu['east_mps']:+.2f}"
                label = "paper (no current)" if cur == "paper" else "water frame (--current)"
                held = "" if c["identifiable"] else " (not identifiable)"
                print(
                    f"| {short[train]} | {label}{held} | " + " | ".join(cells)
                    + f" | {f(pooled(oos, 'rmse_corrected'))} | {imo(oos, 'corrected')}"
                    + f" | {p['m']:+.3f}, {p['b']:+.3f} | {cur_txt} |"
                )
        e = json.loads((j / f"eval-{uut}-2-figure8-paper.json").read_text())["captures"]
        print("| raw | | " + " | ".join(f(r["truth"]["rmse_raw"]) for r in e) + f" | {f(pooled([r['truth'] for r in e], 'rmse_raw'))} | {imo([r['truth'] for r in e], 'raw')} | | |")
        print("| floor | | " + " | ".join(f(r["truth"]["rmse_floor"]) for r in e) + f" | {f(pooled([r['truth'] for r in e], 'rmse_floor'))} | | | |")
    for title, prefix, last in (
        ("the daemon's online KF (replay of the five captures in order), against the truth", "replay",
         "scored samples paper / current"),
        ("from an empty state, automatic lag: straight, circles and return after the transit and the figure-8",
         "replay-after", "lag paper / current (s)"),
    ):
        print(f"\n### {trial}: {title}\n")
        print(f"| UUT | raw | paper (no current) | water frame (current: true) | floor | IMO raw / paper / water frame | {last} |")
        print("|---|---|---|---|---|---|---|")
        rp = json.loads((j / f"{prefix}-paper.json").read_text())["uuts"]
        rc = json.loads((j / f"{prefix}-current.json").read_text())["uuts"]
        for uut in ("emlog1", "emlog2"):
            a, b = rp[uut]["truth"], rc[uut]["truth"]
            tail = (
                f"{a['n_samples']} / {b['n_samples']}" if prefix == "replay"
                else f"{lag_txt(rp[uut]['lag_s'])} / {lag_txt(rc[uut]['lag_s'])}"
            )
            print(
                f"| {uut} | {f(a['rmse_raw'])} | {f(a['rmse_corrected'])} | {f(b['rmse_corrected'])} "
                f"| {f(a['rmse_floor'])} "
                f"| {imo([a], 'raw')} / {imo([a], 'corrected')} / {imo([b], 'corrected')} | {tail} |"
            )
    for uut in ("emlog1", "emlog2"):
        for cur in ("paper", "current"):
            cv = json.loads((j / f"cv-{uut}-{cur}.json").read_text())
            ev = [x for x in cv["evaluations"] if x["train"] == "2-figure8" and x["test"] == "3-straight"]
            print(f"\n{trial} {uut} {cur}: Table II (figure-8 → straight, vs DVL): " + ", ".join(
                f"{x['estimator']} {f(x['rmse_cal_mps'])} ({pct(x['improvement_pct'])})" for x in ev
            ) + f"; raw {f(ev[0]['rmse_raw_mps'])}")
            ov = [x for x in cv["overall"] if x["estimator"] == "LS-EM3"]
            mat = [x for x in cv["evaluations"] if x["estimator"] == "LS-EM3"]
            print(f"{trial} {uut} {cur}: Table III LS-EM3 (vs DVL)")
            for train in names:
                cells = [x for x in mat if x["train"] == train]
                o = next(x for x in ov if x["train"] == train)
                print(f"| {short[train]} | " + " | ".join(
                    f"{f(x['rmse_cal_mps'])} ({pct(x['improvement_pct'])})" + ("*" if x["in_sample"] else "") for x in cells
                ) + f" | {f(o['rmse_cal_mps'])} ({pct(o['improvement_pct'])}) |")
    cv = json.loads((j / "cv-emlog1-emlog2.json").read_text())
    ev = [x for x in cv["evaluations"] if x["train"] == "2-figure8" and x["test"] == "3-straight"]
    print(f"\n{trial} emlog1 vs emlog2: Table II: " + ", ".join(
        f"{x['estimator']} {f(x['rmse_cal_mps'])} ({pct(x['improvement_pct'])})" for x in ev
    ) + f"; raw {f(ev[0]['rmse_raw_mps'])}")
EOF
