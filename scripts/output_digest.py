#!/usr/bin/env python3
"""The outputs of the main job and of the real TIAGo's audit, byte for byte.

A change that only moves code (issue 54: jobs to their floor, files split by concern) must
leave every output byte-identical. This runs `mcms demo` (the embedded default scenario),
the commands of docs/audits.md on examples/ (render, audit cameras, robot, lens and fusion,
calib-rig, report) and the TIAGo audit of docs/tiago.md with its report (when
../shared/data/tiago-mocap is present), hashes every file they write (SHA-256; every command run
with relative paths, so that nothing depends on where the checkout or the data lie), and
compares with tests/golden/output_digest.json.

  scripts/output_digest.py --mcms build/app/mcms --check    # exit 1 naming every file that differs
  scripts/output_digest.py --mcms build/app/mcms --update   # after a change meant to alter outputs

Floating-point results are identical only on the same processor and libraries (OpenCV and
Eigen choose SIMD paths at run time): where the digest was recorded on another processor,
the check says so and exits 77 (ctest: skipped), never a false failure.
"""
import argparse
import hashlib
import json
import os
import subprocess
import sys
import tempfile

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
DIGEST = os.path.join(ROOT, "tests", "golden", "output_digest.json")
SKIP = 77


def processor():
    """The processor's model and SIMD flags: what byte-identical floating point needs."""
    model, flags = "unknown", ""
    try:
        with open("/proc/cpuinfo") as f:
            for line in f:
                key, _, value = line.partition(":")
                if key.strip() == "model name" and model == "unknown":
                    model = value.strip()
                if key.strip() == "flags" and not flags:
                    flags = " ".join(sorted(x for x in value.split() if x.startswith(("sse", "avx", "fma"))))
    except OSError:
        pass
    return model + " | " + flags


def data_dir():
    for d in (os.environ.get("MCMS_DATA_DIR", ""), os.path.join(ROOT, "..", "shared", "data")):
        if d and os.path.isdir(os.path.join(d, "tiago-mocap")):
            return os.path.realpath(d)
    return None


def run(cmd, cwd):
    p = subprocess.run(cmd, cwd=cwd, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    if p.returncode != 0:
        sys.exit(f"output_digest: `{' '.join(cmd)}` failed (exit {p.returncode}):\n{p.stdout[-3000:]}")


def digests(mcms, work):
    """name -> SHA-256 of every output file under `work`.

    Every command runs in `work` with relative paths: the inputs through the links ex/ (the
    checkout's examples/) and data/ (the data folder), the outputs beside them, so no output
    holds a path that depends on where the checkout or the data lie (a path's length shows in
    the sizes the HTML report lists). What is left (the report's absolute folder) is
    replaced by WORK."""
    os.symlink(os.path.join(ROOT, "examples"), os.path.join(work, "ex"))
    jobs = [
        ["demo", "-o", "demo"],
        ["render", "ex/short_scenario.yaml", "-o", "rec"],
        ["audit", "cameras", "rec", "-o", "audit-cameras"],
        ["audit", "robot", "ex/robot_log.csv", "-o", "audit-robot", "--json", "audit-robot.json"],
        ["calib-rig", "ex/boards/board.yaml", "ex/boards/cam0", "-o", "rig-calibration", "-q"],
        ["audit", "lens", "rig-calibration/cam0.cameramodel", "-o", "audit-lens"],
        ["audit", "fusion", "--tracker", "ex/fusion/tracker_poses.csv", "--robot", "ex/fusion/robot_joints.csv",
         "--inclinometer", "ex/fusion/inclinometer.csv", "--setup", "ex/fusion/fusion_setup.yaml", "-o",
         "audit-fusion"],
        ["report", "audit-robot"],
    ]
    data = data_dir()
    if data:
        os.symlink(data, os.path.join(work, "data"))
        t = "data/tiago-mocap/"
        jobs += [["audit", "robot", t + "qualisys_2021-11-30_static_postures.csv", "--robot", t + "tiago_48_hey5.urdf",
                  "--tip-link", "wrist_ft_tool_link", "--validate", t + "qualisys_2021-11-26_static_postures.csv",
                  "-o", "tiago-explained", "-q"],
                 ["report", "tiago-explained"]]
    for cmd in jobs:
        print("mcms " + " ".join(cmd), flush=True)
        run([mcms] + cmd, work)
    out = {}
    real = os.path.realpath(work)
    for dirpath, dirs, files in os.walk(work):
        dirs[:] = [d for d in dirs if not os.path.islink(os.path.join(dirpath, d))]
        for f in sorted(files):
            path = os.path.join(dirpath, f)
            if f == ".mcms-output" or os.path.islink(path):
                continue  # the record of the files (their hashes), checked through them
            with open(path, "rb") as fh:
                b = fh.read()
            b = b.replace(real.encode(), b"WORK").replace(work.encode(), b"WORK")
            out[os.path.relpath(path, work)] = hashlib.sha256(b).hexdigest()
    return out, bool(data)


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--mcms", required=True, help="the mcms executable")
    g = ap.add_mutually_exclusive_group(required=True)
    g.add_argument("--check", action="store_true")
    g.add_argument("--update", action="store_true")
    a = ap.parse_args()
    mcms = os.path.realpath(a.mcms)
    if not os.access(mcms, os.X_OK):
        sys.exit(f"output_digest: --mcms {a.mcms} is not an executable")
    cpu = processor()
    recorded = None
    if a.check:
        try:
            with open(DIGEST) as f:
                recorded = json.load(f)
        except (OSError, ValueError) as e:
            sys.exit(f"output_digest: {DIGEST}: {e}")
        if recorded.get("processor") != cpu:
            print(f"skipped: the digest was recorded on '{recorded.get('processor')}', this is '{cpu}'; "
                  "floating-point outputs are byte-identical only on the same processor (run --update here "
                  "before a change to compare against it)")
            return SKIP
    with tempfile.TemporaryDirectory(prefix="mcms-digest-") as work:
        files, with_data = digests(mcms, work)
    if a.update:
        os.makedirs(os.path.dirname(DIGEST), exist_ok=True)
        with open(DIGEST, "w") as f:
            json.dump({"processor": cpu, "tiago": with_data, "files": files}, f, indent=1, sort_keys=True)
            f.write("\n")
        print(f"recorded {len(files)} files in {os.path.relpath(DIGEST, ROOT)}")
        return 0
    want = recorded["files"]
    if recorded.get("tiago") and not with_data:
        want = {k: v for k, v in want.items() if not k.startswith("tiago-explained" + os.sep)}
        print("the TIAGo data (../shared/data/tiago-mocap) is absent: only the demo compared")
    differ = sorted(k for k in want if k in files and files[k] != want[k])
    missing = sorted(k for k in want if k not in files)
    extra = sorted(k for k in files if k not in want)
    for k in differ:
        print(f"differs: {k}")
    for k in missing:
        print(f"no longer written: {k}")
    for k in extra:
        print(f"new: {k}")
    if differ or missing or extra:
        print(f"{len(differ) + len(missing) + len(extra)} of {len(want)} outputs changed; if the change is meant, "
              "say why in the commit and run --update")
        return 1
    print(f"all {len(want)} outputs byte-identical to {os.path.relpath(DIGEST, ROOT)}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
