#!/usr/bin/env bash
# Regenerate every number and figure of docs/REPRODUCTION.md (about 2 minutes on 2 cores).
# Usage: bash docs/reproduce.sh [OUTDIR]   (needs: pip install '.[report]')
set -euo pipefail
out="${1:-/tmp/emlogd-trial}"
emlogd() { "${EMLOGD:-emlogd}" "$@"; }
time emlogd simulate "$out" --seed 1
caps=("$out"/1-transit.cap "$out"/2-figure8.cap "$out"/3-straight.cap "$out"/4-circles.cap "$out"/5-return.cap)
echo "== EMlog1 vs DVL"
time emlogd crossval "${caps[@]}" --uut emlog1 --ref dvl --estimator LS-EM3 --estimator KF-EM3 --csv "$out/cv-emlog1-dvl.csv"
echo "== EMlog2 vs DVL"
emlogd crossval "${caps[@]}" --uut emlog2 --ref dvl --estimator LS-EM3
echo "== EMlog1 vs EMlog2 (relative)"
emlogd crossval "${caps[@]}" --uut emlog1 --ref emlog2 --ref-field speed --estimator LS-EM3
echo "== identifiability of the straight run"
emlogd calibrate "$out"/3-straight.cap --uut emlog1 --ref dvl --lag 3.3
echo "== KF-EM3 on the figure-8"
emlogd calibrate "$out"/2-figure8.cap --uut emlog1 --ref dvl --method kf
emlogd report "${caps[@]}" --uut emlog1 --ref dvl --out "$out/figures"
