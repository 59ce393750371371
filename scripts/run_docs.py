#!/usr/bin/env python3
"""Runs every shell command the Markdown pages show, so the docs cannot rot.

    run_docs.py --build BUILD_DIR [PAGE.md ...] [--section HEADING] [--keep DIR]
                [--not-run PAGE=REASON ...] [--listing FILE]
    run_docs.py --build BUILD_DIR --self-test    # a failing command fails the run

Pages: README.md, every docs/*.md and examples/README.md of this checkout when none are given.

Which lines are commands (decided per block, the same way on every page):
- a fenced block whose info string is sh, bash, shell or console: every line;
- an indented block (lines of 4 spaces after a blank line, outside fences) whose first line
  starts with a command: `mcms`, `cd`, `cp`, `python3`, `/usr/bin/python3`, `cmp`, `diff`,
  `ls`, `./scripts/...`, `./build/...`, `build/...` or `examples/...`, optionally after
  `VAR=value` assignments, or a line that is one `VAR=value` assignment (a path the next
  lines use).
  Other indented blocks (Python, formulas) and plain fences (diagrams) are not commands.
A trailing backslash continues a command; `#` comment lines are skipped, trailing comments
are kept (bash ignores them). Commands written inline in the prose (synopses like
`mcms audit robot LOG.csv [--robot ROBOT.yaml]`) are not run.

A block that cannot run in a test (set-up, builds, clusters, long benchmarks, fuzzing) is
marked in the page by an HTML comment on the line(s) before it, `<!-- not run: REASON -->`;
it is listed as not run with the reason, never silently skipped. A block that reads real data
(../shared/data, as from the checkout) is marked `<!-- needs data: NAME -->`: it runs when
that data set is present ($MCMS_DATA_DIR or ../shared/data beside the checkout; the page's
folder sees it at ../shared/data) and is listed as not run, "real data not present", when not.

How they run: each page in its own fresh folder (one bash session; every block starts in
the page's folder and a `cd` carries over to the rest of its block), which holds a copy of
the checkout's examples/ and `build`, a link to BUILD_DIR, so that the docs' paths
(`examples/robot_log.csv`, `build/python`) work as from the checkout; `mcms` is on the PATH from BUILD_DIR/app, and $EXAMPLES is the copied
examples/. A page whose first commands are the same as an earlier page's (same text, up to
a trailing comment, started from the same fresh folder) takes that page's folder as it was
after them instead of running them again, e.g. the demo shown by three pages runs once;
the listing says so. Every command is listed with its page and line, its status and its
time (also written to --listing FILE); the first failure of a page stops that page, shows
its output and lists the page's remaining commands as not reached. Exit status 0 when
every command ran and succeeded, 1 when one failed, 2 on bad arguments.
"""
import argparse
import os
import re
import shutil
import subprocess
import sys
import tempfile
import time

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
SHELL_INFO = {"sh", "bash", "shell", "console"}
COMMAND_START = re.compile(r"^(\w+=\S*\s+)*(mcms|cd|cp|python3|/usr/bin/python3|cmp|diff|ls|\./scripts/\S*|"
                           r"\./build/\S*|build/\S*|examples/\S*)(\s|$)|^\w+=\S*\s*$")
NOT_RUN = re.compile(r"^\s*<!--\s*not run:\s*(.*?)\s*-->\s*$")
NEEDS_DATA = re.compile(r"^\s*<!--\s*needs data:\s*(\S+)\s*-->\s*$")


def data_root():
    """The real data: $MCMS_DATA_DIR, or ../shared/data beside the checkout."""
    return os.environ.get("MCMS_DATA_DIR") or os.path.join(os.path.dirname(ROOT), "shared", "data")


class Block:
    def __init__(self, line, commands, not_run):
        self.line = line          # 1-based line of the block's first command
        self.commands = commands  # [(line, text)]
        self.not_run = not_run    # reason, or None


def join_commands(lines):
    """[(line, text)] -> commands, joining backslash continuations, dropping comment lines."""
    out, cur, start = [], "", None
    for n, l in lines:
        l = l.rstrip()
        if not cur and (not l.strip() or l.lstrip().startswith("#")):
            continue
        if l.startswith("$ ") and not cur:
            l = l[2:]
        if start is None:
            start = n
        cur += l.lstrip() if cur else l
        if cur.endswith("\\"):
            cur = cur[:-1].rstrip() + " "
            continue
        out.append((start, cur))
        cur, start = "", None
    if cur:
        out.append((start, cur))
    return out


def blocks(page, section=None):
    lines = open(page, encoding="utf-8").read().split("\n")
    lo, hi = 0, len(lines)
    if section:
        lo = next((i for i, l in enumerate(lines) if l.startswith("#") and l.lstrip("#").strip() == section), None)
        if lo is None:
            raise SystemExit(f"run_docs: {page} has no section '{section}'")
        hi = next((i for i in range(lo + 1, len(lines)) if lines[i].startswith("#")), len(lines))
    out, i, pending, prev_blank = [], lo, None, True
    while i < hi:
        l = lines[i]
        m = NOT_RUN.match(l)
        if m:
            pending, prev_blank = m.group(1), True
            i += 1
            continue
        m = NEEDS_DATA.match(l)
        if m:
            if not os.path.isdir(os.path.join(data_root(), m.group(1))):
                pending = f"real data not present: {os.path.join(data_root(), m.group(1))}"
            prev_blank = True
            i += 1
            continue
        fence = re.match(r"^(```+|~~~+)\s*(\S*)", l)
        if fence:
            j = i + 1
            while j < hi and not lines[j].startswith(fence.group(1)):
                j += 1
            if fence.group(2).lower() in SHELL_INFO:
                cmds = join_commands([(k + 1, lines[k]) for k in range(i + 1, j)])
                if cmds:
                    out.append(Block(cmds[0][0], cmds, pending))
            pending, prev_blank, i = None, False, j + 1
            continue
        if l.startswith("    ") and l.strip() and prev_blank:
            j = i
            while j < hi and lines[j].startswith("    ") and lines[j].strip():
                j += 1
            if COMMAND_START.match(l[4:]):
                cmds = join_commands([(k + 1, lines[k][4:]) for k in range(i, j)])
                out.append(Block(cmds[0][0], cmds, pending))
            pending, prev_blank, i = None, False, j
            continue
        if l.strip():
            pending = None if not l.lstrip().startswith("<!--") else pending
        prev_blank = not l.strip()
        i += 1
    return out


def normal(cmd):
    """A command without its trailing comment and extra spaces (for comparing pages)."""
    return " ".join(re.sub(r"\s+#[^'\"]*$", "", cmd).split())


def rel(page):
    r = os.path.relpath(page, ROOT)
    return os.path.basename(page) if r.startswith("..") else r


SELF_TEST_PAGES = {
    "good.md": """# Good

    mcms --help > /dev/null     # a command

```sh
mcms audit --help \\
  > /dev/null
```

```
    mcms no-such-command        # in a plain fence: a diagram, not a command
```

    import os                   # an indented block that is not a command

<!-- not run: a marked block -->

    mcms no-such-command

<!-- needs data: no-such-data-set -->

    mcms audit robot ../shared/data/no-such-data-set/log.csv
""",
    "bad.md": """# Bad

    mcms --help > /dev/null
    mcms no-such-command
    mcms --help > /dev/null
""",
}


LISTING = []


def say(*args):
    """Prints a line of the listing and keeps it for --listing."""
    line = " ".join(str(x) for x in args)
    print(line)
    LISTING.append(line)


def self_test(argv):
    """Runs this script on SELF_TEST_PAGES: the good page must pass with 2 commands ok and
    2 not run (one marked, one whose real data is absent); the bad one must fail, name the
    failing command and stop there."""
    me = os.path.abspath(__file__)
    with tempfile.TemporaryDirectory(prefix="mcms_docs_self_") as tmp:
        paths = {}
        for name, text in SELF_TEST_PAGES.items():
            paths[name] = os.path.join(tmp, name)
            open(paths[name], "w").write(text)
        good = subprocess.run([sys.executable, me, *argv, paths["good.md"]], capture_output=True, text=True)
        bad = subprocess.run([sys.executable, me, *argv, paths["bad.md"]], capture_output=True, text=True)
    print(good.stdout + good.stderr + bad.stdout + bad.stderr)
    problems = []
    if good.returncode != 0 or "2 commands ok, 0 reused, 2 not run, 0 failed" not in good.stdout \
            or "real data not present" not in good.stdout:
        problems.append(f"the good page should pass with 2 commands ok and 2 not run (exit {good.returncode})")
    if bad.returncode != 1 or not re.search(r"^FAIL .*mcms no-such-command", bad.stdout, re.M) \
            or "1 commands ok, 0 reused, 0 not run, 1 failed" not in bad.stdout or "not reached  bad.md:5" not in bad.stdout:
        problems.append(f"the bad page should fail at its 2nd command and stop (exit {bad.returncode})")
    for m in problems:
        print("run_docs --self-test: " + m, file=sys.stderr)
    print("run_docs --self-test: " + ("FAILED" if problems else "passed"))
    return 1 if problems else 0


def main():
    if "--self-test" in sys.argv:
        return self_test([x for x in sys.argv[1:] if x != "--self-test"])
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("pages", nargs="*")
    p.add_argument("--build", help="the CMake build folder (mcms is BUILD/app/mcms)")
    p.add_argument("--bin", help="folder of the mcms executable (default BUILD/app)")
    p.add_argument("--section", help="run only this section (heading text) of each page")
    p.add_argument("--listing", help="also write the listing to this file")
    p.add_argument("--keep", help="run in this folder (one sub-folder per page) and keep it")
    p.add_argument("--not-run", action="append", default=[], metavar="PAGE=REASON",
                   help="list this page's commands as not run, with the reason (e.g. a part not built)")
    a = p.parse_args()
    if not a.build and not a.bin:
        p.error("give --build (or --bin)")
    build = os.path.abspath(a.build) if a.build else os.path.dirname(os.path.abspath(a.bin))
    bindir = os.path.abspath(a.bin) if a.bin else os.path.join(build, "app")
    if not os.access(os.path.join(bindir, "mcms"), os.X_OK):
        print(f"run_docs: {bindir}/mcms not found or not executable", file=sys.stderr)
        return 2
    pages = a.pages or [os.path.join(ROOT, "README.md")] + sorted(
        os.path.join(ROOT, "docs", f) for f in os.listdir(os.path.join(ROOT, "docs")) if f.endswith(".md")) + [
            os.path.join(ROOT, "examples", "README.md")]
    skipped = {}
    for s in a.not_run:
        page, _, reason = s.partition("=")
        skipped[os.path.abspath(page) if os.path.exists(page) else os.path.join(ROOT, page)] = reason or "excluded"
    examples = os.path.join(ROOT, "examples")
    env = dict(os.environ, PATH=bindir + os.pathsep + os.environ.get("PATH", ""))
    env.pop("PYTHONPATH", None)

    work_root = os.path.abspath(a.keep) if a.keep else tempfile.mkdtemp(prefix="mcms_docs_")
    os.makedirs(work_root, exist_ok=True)
    t_all = time.time()
    counts = {"ok": 0, "reused": 0, "not run": 0, "FAIL": 0}
    failed_pages = []
    # Runnable commands of each page, in order: (line, text, normalised)
    plan = []
    for page in pages:
        bs = blocks(page, a.section)
        plan.append((page, bs))
    # Shared prefixes: for each page, the earlier page and the number of leading commands it
    # shares with it; snapshots are taken in the earlier page after that many commands.
    # (line, text, normalised, first of its block)
    runnable = [[(n, c, normal(c), k == 0) for b in bs if not b.not_run and page not in skipped
                 for k, (n, c) in enumerate(b.commands)] for page, bs in plan]
    share = [None] * len(plan)
    snaps = {}
    for i in range(len(plan)):
        best = (None, 0)
        for j in range(i):
            k = 0
            while k < min(len(runnable[i]), len(runnable[j])) and runnable[i][k][2] == runnable[j][k][2]:
                k += 1
            if k > best[1]:
                best = (j, k)
        if best[0] is not None:
            share[i] = best
            snaps.setdefault(best[0], set()).add(best[1])

    listing = []
    for i, (page, bs) in enumerate(plan):
        name = rel(page)
        say(f"== {name}")
        sys.stdout.flush()
        if not bs:
            say("   (shows no shell command)")
            continue
        folder = os.path.join(work_root, re.sub(r"[^\w.-]", "_", name))
        shutil.rmtree(folder, ignore_errors=True)
        cmds = runnable[i]
        start, cwd0, entries = 0, folder, []
        if share[i]:
            j, k = share[i]
            snap = os.path.join(work_root, f".snap-{j}-{k}")
            if os.path.isdir(snap) and os.path.exists(snap + ".cwd"):
                shutil.copytree(snap, folder, symlinks=True)
                cwd0 = os.path.join(folder, open(snap + ".cwd").read().strip())
                start = k
                for n, c, _, _ in cmds[:k]:
                    entries.append((n, f"same {'':>6}  {name}:{n}  {c}   (as {rel(plan[j][0])} ran it from the same "
                                       "files: its results reused)"))
                    counts["reused"] += 1
        if start == 0:
            shutil.copytree(examples, os.path.join(folder, "examples"))
            os.symlink(build, os.path.join(folder, "build"))
        # The real data where the docs say it is: ../shared/data from the page's folder.
        shared = os.path.join(work_root, "shared")
        if os.path.isdir(data_root()) and not os.path.exists(shared):
            os.makedirs(shared)
            os.symlink(os.path.abspath(data_root()), os.path.join(shared, "data"))
        # Not-run blocks are listed where they stand; runnable commands run in one bash session.
        for b in bs:
            if b.not_run or page in skipped:
                for n, c in b.commands:
                    entries.append((n, f"not run      {name}:{n}  {c}   (not run: {b.not_run or skipped[page]})"))
                    counts["not run"] += 1
        if start >= len(cmds):
            for _, e in sorted(entries):
                say(e)
            continue
        script = "set -o pipefail\n"
        for k in range(start, len(cmds)):
            n, c, _, first = cmds[k]
            if first:  # every block starts in the page's folder (the checkout's, as the docs assume)
                script += f"cd '{folder}'\n"
            script += f"echo '@@start {k}' >&2; SECONDS=0\n{c}\nrc=$?; echo \"@@done {k} $rc $SECONDS\" >&2\n"
            script += "[ $rc -eq 0 ] || exit $rc\n"
            if k + 1 in snaps.get(i, ()):
                snap = os.path.join(work_root, f".snap-{i}-{k + 1}")
                script += (f"realpath --relative-to='{folder}' \"$PWD\" > '{snap}.cwd'; "
                           f"cp -a '{folder}' '{snap}'\n")
        r = subprocess.run(["bash", "-c", script], cwd=cwd0, env=dict(env, EXAMPLES=os.path.join(folder, "examples")),
                           capture_output=True, text=True)
        status = {}
        for l in r.stderr.splitlines():
            if l.startswith("@@done "):
                _, k, code, secs = l.split()
                status[int(k)] = (int(code), int(secs))
        for k in range(start, len(cmds)):
            n, c, _, _ = cmds[k]
            code, secs = status.get(k, (None, 0))
            if code is None:
                entries.append((n, f"FAIL {'':>6}  {name}:{n}  {c}   (did not finish: bash exited {r.returncode})"))
                counts["FAIL"] += 1
                break
            ok = code == 0
            entries.append((n, f"{'ok  ' if ok else 'FAIL'} {secs:4d} s  {name}:{n}  {c}" + ("" if ok else f"   (exit {code})")))
            counts["ok" if ok else "FAIL"] += 1
            if not ok:
                for n2, c2, _, _ in cmds[k + 1:]:
                    entries.append((n2, f"not reached  {name}:{n2}  {c2}   (after the failure above)"))
                break
        for _, e in sorted(entries):
            say(e)
        sys.stdout.flush()
        if r.returncode != 0 or len(status) < len(cmds) - start:
            failed_pages.append(name)
            say(f"--- {name}: output (last 3000 characters of stdout, then stderr)")
            say(r.stdout[-3000:])
            say("\n".join(l for l in r.stderr.splitlines() if not l.startswith("@@"))[-3000:])
    say(f"run_docs: {len(pages)} pages, {counts['ok']} commands ok, {counts['reused']} reused, "
          f"{counts['not run']} not run, {counts['FAIL']} failed ({time.time() - t_all:.0f} s)"
          + (f"; failed: {', '.join(failed_pages)}" if failed_pages else ""))
    if a.listing:
        os.makedirs(os.path.dirname(os.path.abspath(a.listing)), exist_ok=True)
        with open(a.listing, "w") as f:
            f.write("\n".join(LISTING) + "\n")
    if not a.keep:
        shutil.rmtree(work_root, ignore_errors=True)
    return 1 if failed_pages else 0


if __name__ == "__main__":
    sys.exit(main())
