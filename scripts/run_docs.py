#!/usr/bin/env python3
"""Runs the shell commands a Markdown page shows, so the docs cannot rot.

    run_docs.py PAGE.md --section "A five-minute tour" --bin build/app [--workdir DIR]

Every indented code line (4 spaces) of the section is a command (a trailing backslash
continues it; `# ...` comments are kept, bash ignores them). They run in order in one bash
session in a fresh temporary folder (so `cd` carries over), `mcms` found on the PATH from
--bin. Prints each command with its exit status and time; exits 1 at the first failure
(its output shown), 2 on bad arguments.
"""
import argparse
import os
import subprocess
import sys
import tempfile
import time


def commands(page, section):
    lines = open(page, encoding="utf-8").read().split("\n")
    start = next((i for i, l in enumerate(lines) if l.startswith("#") and l.lstrip("#").strip() == section), None)
    if start is None:
        raise SystemExit(f"run_docs: {page} has no section '{section}'")
    out, cur = [], ""
    for l in lines[start + 1:]:
        if l.startswith("#") and not l.startswith("    "):
            break
        if not l.startswith("    "):
            continue
        cur += l[4:].rstrip()
        if cur.endswith("\\"):
            cur = cur[:-1] + " "
            continue
        out.append(cur)
        cur = ""
    return out


def main():
    p = argparse.ArgumentParser()
    p.add_argument("page")
    p.add_argument("--section", required=True)
    p.add_argument("--bin", required=True, help="folder of the mcms executable")
    p.add_argument("--workdir", help="run here instead of a fresh temporary folder")
    a = p.parse_args()
    if not os.access(os.path.join(a.bin, "mcms"), os.X_OK):
        print(f"run_docs: {a.bin}/mcms not found or not executable", file=sys.stderr)
        return 2
    cmds = commands(a.page, a.section)
    if not cmds:
        print(f"run_docs: section '{a.section}' of {a.page} shows no command", file=sys.stderr)
        return 2
    env = dict(os.environ, PATH=os.path.abspath(a.bin) + os.pathsep + os.environ.get("PATH", ""))
    with tempfile.TemporaryDirectory(prefix="mcms_docs_") as tmp:
        work = a.workdir or tmp
        os.makedirs(work, exist_ok=True)
        # One bash session: a marker after each command reports its status.
        script = "set -o pipefail\n"
        for k, c in enumerate(cmds):
            script += f"echo '@@start {k}' >&2; SECONDS=0\n{c}\necho \"@@done {k} $? $SECONDS\" >&2\n"
        t0 = time.time()
        r = subprocess.run(["bash", "-c", script], cwd=work, env=env, capture_output=True, text=True)
        status = {}
        for l in r.stderr.splitlines():
            if l.startswith("@@done "):
                _, k, code, secs = l.split()
                status[int(k)] = (int(code), int(secs))
        for k, c in enumerate(cmds):
            code, secs = status.get(k, (None, 0))
            print(f"{'ok  ' if code == 0 else 'FAIL'} {secs:4d} s  {c}")
            if code != 0:
                print(r.stdout[-3000:])
                print(r.stderr[-3000:], file=sys.stderr)
                return 1
        print(f"run_docs: {len(cmds)} commands of '{a.section}' in {a.page} ran ({time.time() - t0:.0f} s)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
