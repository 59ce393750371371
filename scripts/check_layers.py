#!/usr/bin/env python3
"""The include rules of the layers (docs/architecture.md), checked from the code.

Layers, bottom to top: core, vision, model, tracking, calib, fusion, synthetic, audit,
jobs, app. A file of a layer may include the project's headers of its own layer and of
the layers below it, never above; and no two modules (a header with its source) of one
layer include each other (a module is a header with its source, and X_internal.h belongs to
module X). Every job (a file named *_job.h/.cpp, or one declaring a `Run...Job(` function) sits
on the jobs floor, jobs/. python/, bench/, fuzz/ and tests/ sit on top and may include any layer. Exit status 1, with one line per broken rule (file, line, what it includes and
why that is upward or mutual), when a rule is broken.

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
                    for number, line in enumerate(f, 1):
                        j = JOB.match(line)
                        if j and layer in rank and layer not in ("jobs", "app"):
                            problems.append(f"{rel}:{number}: declares the job {j.group(1)} outside the jobs floor "
                                            f"(jobs/)")
                        m = INCLUDE.match(line)
                        if not m:
                            continue
                        to_layer, to_module = m.group(1), m.group(2)
                        if to_layer not in rank and to_layer not in TOP:
                            continue
                        if layer in rank and to_layer in rank and rank[to_layer] > rank[layer]:
                            problems.append(f"{rel}:{number}: includes {to_layer}/{to_module}.h, an upper layer "
                                            f"({layer} is below {to_layer}; layers bottom to top: {' '.join(LAYERS)})")
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
          "including each other, every job in jobs/)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
