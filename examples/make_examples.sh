#!/bin/bash
# Remakes every file of examples/ (examples/README.md says what each is) with our own
# commands, from the checkout's folder, with `mcms` on the PATH:
#   export PATH=$PWD/build/app:$PATH && examples/make_examples.sh
# Everything is seeded: the files come out the same on every run (about 1 min on 2 cores).
# No command renders board images: examples/make_boards.py does (numpy, cv2).
set -euo pipefail
cd "$(dirname "$0")/.."
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT

# The example robots as URDF too (their forward kinematics equal the DH tables'; docs/urdf.md).
mcms convert-robot -o examples/robots/kuka_kr5_arc.urdf > /dev/null  # the built-in KR 5 arc
mcms convert-robot examples/robots/ur10_like.yaml -o examples/robots/ur10_like.urdf > /dev/null

# The robot log with a hidden joint-3 offset (CSV for audit robot, YAML for calib-robot).
python3 examples/make_robot_log.py --out examples

# Chessboard images of one camera, for calib-rig (and its model for audit lens); Debian's
# interpreter has cv2 and numpy.
/usr/bin/python3 examples/make_boards.py --out examples/boards

# Fusion logs: the demo's own, 3 points with 2 camera frames a second (48 tracked frames,
# enough pairs for the inclinometer audit), joints and inclinometer thinned from 50 to 10 Hz
# (every 5th row) to keep the files small; the setup's inclinometer period says so.
mcms demo -q -o "$tmp/demo" --points 3 --camera-rate 2 --no-iso9283 --no-html > /dev/null
mkdir -p examples/fusion
for f in robot_joints inclinometer; do
  awk 'NR == 1 || NR % 5 == 2' "$tmp/demo/$f.csv" > "examples/fusion/$f.csv"
done
cp "$tmp/demo/tracker_poses.csv" "$tmp/demo/dwells.csv" examples/fusion/
sed 's/^  period_s: 0.02$/  period_s: 0.1/' "$tmp/demo/fusion_setup.yaml" > examples/fusion/fusion_setup.yaml

# ISO 9283: the attained poses (30 cycles of P1..P5) and path runs of the demo's ISO 9283
# experiment, condition 1 (the uncalibrated robot).
mcms iso9283 --simulate --cycles 30 --write-measurements "$tmp/iso" > /dev/null
mkdir -p examples/iso9283
cp "$tmp/iso/attained_1.csv" examples/iso9283/poses.csv
cp "$tmp/iso/path_1.csv" examples/iso9283/path.csv

# A 2 s scenario: the embedded default with 20 frames instead of 120.
{
  echo '# The embedded default scenario (`mcms render --print-default`) with 20 frames instead of 120:'
  echo "# a 2 s recording that renders in seconds, for the docs' examples (examples/README.md)."
  mcms render --print-default | sed 's/^  frames: 120$/  frames: 20/; s/^# 120 frames at 10 Hz/# 20 frames at 10 Hz/'
} > examples/short_scenario.yaml
echo "examples/: remade"
