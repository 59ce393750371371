#!/usr/bin/env python3
"""The include rules of the layers (docs/architecture.md), checked from the code.

Layers, bottom to top: core, vision, model, tracking, calib, fusion, synthetic, audit,
jobs, app. A file of a layer may include the project's headers of its own layer and of
the layers below it, never above; and no two modules (a header with its source) of one
layer include each other (a module is a header with its source, and X_internal.h belongs to
module X). Every job (a file named *_job.h/.cpp, or one declaring a `Run...Job(` function) sits
on the jobs floor, jobs/, declared with the one signature `void RunXJob(const XJob& job,
const JobOutput& out);` (jobs/job.h). The audit stands on model/ and includes nothing from calib/ (both
read the robot's measurements from model/; neither climbs into the other). No source file
is longer than 900 lines unless a line `// Long file: <why>` in its first 30 lines says why
(one concern per file). python/, bench/, fuzz/ and tests/ sit on top and may include any
layer. Exit status 1, with one line per broken rule (file, line, what it includes and why
that is upward or mutual), when a rule is broken.

  scripts/check_layers.py [ROOT]      # the tree at ROOT (default: this checkout)
  scripts/check_layers.py --self-test # shows that an upward and a mutual include fail
"""
import os
import re
import shutil
import subprocess
import sys
import tempfile

LAYERS = ["core", "vision", "model", "tracking", "calib", "fusion", "synthetic", "audit", "jobs", "app"]
TOP = ["python", "bench", "fuzz", "tests"]
INCLUDE = re.compile(r'^\s*#\s*include\s+"([a-z_]+)/([A-Za-z0-9_]+)\.h"')
JOB = re.compile(r'^[A-Za-z_][\w:<>, ]*\s(Run\w*Job)\s*\(')
MAX_LINES = 900
LONG_REASON = re.compile(r'^\s*(//|#)\s*Long file:\s*\S')
# (layer, layer it must not include) beyond the floors' order: the audit confronts the
# model with measurements; it never calls the calibration that fits it.
FORBIDDEN = {("audit", "calib"): "the audit includes nothing from calib/ (it stands on model/)"}


def check(root):
    rank = {name: i for i, name in enumerate(LAYERS)}
    problems = []
    module_deps = {}  # "layer/module" -> set of "layer/module" it includes
    for layer in LAYERS + TOP:
        folder = os.path.join(root, layer)
        if not os.path.isdir(folder):
            continue
        for dirpath, _, files in os.walk(folder):
            for name in sorted(files):
                if not name.endswith((".h", ".cpp", ".cc", ".in")):
                    continue
                path = os.path.join(dirpath, name)
                rel = os.path.relpath(path, root)
                # A module is a header with its source; X_internal.h (declarations X shares with
                # the rest of its layer) belongs to module X.
                module = layer + "/" + re.sub(r"_internal$", "", name.rsplit(".", 1)[0])
                if layer in rank and layer not in ("jobs", "app") and re.search(r"_job\.(h|cpp)$", name):
                    problems.append(f"{rel}: a job outside the jobs floor (move it to jobs/)")
                with open(path, encoding="utf-8", errors="replace") as f:
                    lines = f.readlines()
                if len(lines) > MAX_LINES and not any(LONG_REASON.match(x) for x in lines[:30]):
                    problems.append(f"{rel}: {len(lines)} lines, over {MAX_LINES}, with no '// Long file: <why>' in "
                                    f"its first 30 lines (split it by concern, or say why not)")
                for number, line in enumerate(lines, 1):
                    j = JOB.match(line)
                    if j and layer in rank and layer not in ("jobs", "app"):
                        problems.append(f"{rel}:{number}: declares the job {j.group(1)} outside the jobs floor "
                                        f"(jobs/)")
                    if j and layer == "jobs" and name.endswith("_job.h") and not re.match(
                            r"^void Run\w*Job\(const \w+Job& \w+, const JobOutput& \w+\);", line):
                        problems.append(f"{rel}:{number}: the job {j.group(1)} is not declared as every job is: "
                                        f"void RunXJob(const XJob& job, const JobOutput& out); (jobs/job.h)")
                    m = INCLUDE.match(line)
                    if not m:
                        continue
                    to_layer, to_module = m.group(1), m.group(2)
                    if to_layer not in rank and to_layer not in TOP:
                        continue
                    if layer in rank and to_layer in rank and rank[to_layer] > rank[layer]:
                        problems.append(f"{rel}:{number}: includes {to_layer}/{to_module}.h, an upper layer "
                                        f"({layer} is below {to_layer}; layers bottom to top: {' '.join(LAYERS)})")
                    if (layer, to_layer) in FORBIDDEN:
                        problems.append(f"{rel}:{number}: includes {to_layer}/{to_module}.h: "
                                        f"{FORBIDDEN[(layer, to_layer)]}")
                    if layer in rank and to_layer in TOP:
                        problems.append(f"{rel}:{number}: includes {to_layer}/{to_module}.h; {to_layer}/ sits on "
                                        f"top of every layer")
                    target = to_layer + "/" + re.sub(r"_internal$", "", to_module)
                    if layer in rank and target != module:
                        module_deps.setdefault(module, set()).add(target)
    for a, deps in sorted(module_deps.items()):
        for b in sorted(deps):
            if a < b and a in module_deps.get(b, set()):
                problems.append(f"{a} and {b} include each other (a module may use the other, not both ways)")
    return problems


def self_test():
    """A copy of the tree with an upward include, then a mutual one: each must fail."""
    root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    ok = True
    with tempfile.TemporaryDirectory() as tmp:
        for layer in LAYERS:
            if os.path.isdir(os.path.join(root, layer)):
                shutil.copytree(os.path.join(root, layer), os.path.join(tmp, layer),
                                ignore=shutil.ignore_patterns("*.o", "*.a"))
        clean = check(tmp)
        if clean:
            print("self-test: the unchanged tree already breaks a rule:\n  " + "\n  ".join(clean))
            ok = False
        # An upward include: the ground floor using the fusion.
        with open(os.path.join(tmp, "core", "io.h"), "a") as f:
            f.write('\n#include "fusion/moifa.h"\n')
        upward = check(tmp)
        print("self-test, core/io.h including fusion/moifa.h:\n  " + ("\n  ".join(upward) or "(nothing found)"))
        ok = ok and any("core/io.h" in p and "upper layer" in p for p in upward)
        # A mutual include inside one layer.
        with open(os.path.join(tmp, "core", "io.h")) as f:
            text = f.read().replace('#include "fusion/moifa.h"\n', "")
        with open(os.path.join(tmp, "core", "io.h"), "w") as f:
            f.write(text)
        with open(os.path.join(tmp, "core", "random.h"), "a") as f:
            f.write('\n#include "core/io.h"\n')
        with open(os.path.join(tmp, "core", "io.cpp"), "a") as f:
            f.write('\n#include "core/random.h"\n')
        mutual = check(tmp)
        print("self-test, core/random.h and core/io.cpp including each other:\n  " +
              ("\n  ".join(mutual) or "(nothing found)"))
        ok = ok and any("include each other" in p for p in mutual)
        # A job on the wrong floor.
        with open(os.path.join(tmp, "audit", "stray_job.h"), "w") as f:
            f.write("#pragma once\nvoid RunStrayJob(int);\n")
        stray = check(tmp)
        print("self-test, audit/stray_job.h declaring RunStrayJob:\n  " + ("\n  ".join(
            p for p in stray if "stray" in p) or "(nothing found)"))
        ok = ok and sum("stray_job.h" in p and "jobs floor" in p for p in stray) == 2
        # A job of another signature.
        with open(os.path.join(tmp, "jobs", "stray_job.h"), "w") as f:
            f.write("#pragma once\nstd::string RunStrayJob(const StrayJob& job);\n")
        other = [p for p in check(tmp) if "stray_job.h" in p]
        print("self-test, jobs/stray_job.h returning a string:\n  " + ("\n  ".join(other) or "(nothing found)"))
        ok = ok and any("not declared as every job is" in p for p in other)
        os.remove(os.path.join(tmp, "jobs", "stray_job.h"))
        # The audit climbing into calib.
        with open(os.path.join(tmp, "audit", "stray_job.h"), "w") as f:
            f.write('#pragma once\n#include "calib/robot_calibration.h"\n')
        climb = [p for p in check(tmp) if "stray_job.h:2" in p]
        print("self-test, audit/stray_job.h including calib/robot_calibration.h:\n  " + ("\n  ".join(climb) or
                                                                                        "(nothing found)"))
        ok = ok and any("nothing from calib" in p for p in climb)
        os.remove(os.path.join(tmp, "audit", "stray_job.h"))
        # A long file without its reason, then with it.
        long_file = os.path.join(tmp, "core", "stray_long.cpp")
        with open(long_file, "w") as f:
            f.write("// one concern too many\n" + "int x;\n" * (MAX_LINES + 1))
        long_found = [p for p in check(tmp) if "stray_long.cpp" in p]
        print("self-test, core/stray_long.cpp of " + str(MAX_LINES + 2) + " lines:\n  " +
              ("\n  ".join(long_found) or "(nothing found)"))
        ok = ok and any("over 900" in p for p in long_found)
        with open(long_file, "w") as f:
            f.write("// Long file: one table, generated\n" + "int x;\n" * (MAX_LINES + 1))
        ok = ok and not any("stray_long.cpp" in p for p in check(tmp))
    print("self-test " + ("passed" if ok else "FAILED"))
    return 0 if ok else 1


def main():
    if len(sys.argv) > 1 and sys.argv[1] == "--self-test":
        return self_test()
    root = sys.argv[1] if len(sys.argv) > 1 else os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    problems = check(root)
    for p in problems:
        print(p)
    if problems:
        print(f"{len(problems)} include rule(s) broken (docs/architecture.md)")
        return 1
    print("include rules hold: " + " <- ".join(LAYERS) + " (no upward include, no two modules of a layer "
          "including each other, every job in jobs/ with one signature, audit nothing from calib, no file over "
          f"{MAX_LINES} lines without its reason)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
