"""mcms batch: track many recordings on Dask distributed and collect one table.

    python3 -m mcms_batch DIR_OR_LIST -o OUT [--scheduler ADDR] [--workers N] ...

(what `mcms batch` runs). DIR_OR_LIST is a folder whose sub-folders are recordings (a
sub-folder holding images/ or rig.yaml, as `mcms render` writes them), or a text file with
one recording folder per line (blank lines and lines starting with '#' skipped; relative
paths are relative to the list file's folder). Each recording is one Dask task that calls
mcms.track_recording in a worker process and writes OUT/<name>/poses.csv. A recording that
fails (bad input, an exception, a worker process that dies under it) becomes a row with
status "failed" and the message; the others go on. OUT/summary.csv holds one row per
recording, in input order, and is written atomically at the end.

Without --scheduler a local cluster of --workers processes is started (and stopped at the
end); with --scheduler ADDR the recordings go to that scheduler's workers, which must be
able to `import mcms` and `import mcms_batch` (PYTHONPATH holding the build's python/
folder).

Recordings are handed to the workers no faster than their threads take them, so a worker
process that dies (a crash, out of memory) takes only the recording it was tracking with it:
that recording fails with "the worker process died while tracking it" and is not retried
(on the local cluster; a scheduler given with --scheduler applies its own
distributed.scheduler.allowed-failures, Dask's default retries it on 3 more workers). A
recording Dask had already handed to the dying worker but not begun goes back in the queue.

Exit status: 0 when at least one recording was tracked (failures are in the table), 3 when
every recording failed, 2 on bad input (no recordings, a missing folder or list, an output
that is not a folder, a scheduler that cannot be reached).

Test hook: when the environment variable MCMS_BATCH_TEST_DIE_ON names a recording (its
folder's base name), the worker process tracking it exits at once (os._exit), as a crash
would; the tests use it to check that a dead worker fails that recording only.
"""
import argparse
import csv
import logging
import os
import sys
import tempfile
import time

COLUMNS = ["name", "status", "frames", "ok", "degraded", "lost", "err_pos_rms_mm", "err_rot_rms_deg", "nees",
           "nees_consistent", "seconds", "output", "message"]


class BatchInputError(Exception):
    """Bad input of the batch as a whole (exit 2)."""


def is_recording(path):
    return os.path.isdir(os.path.join(path, "images")) or os.path.isfile(os.path.join(path, "rig.yaml"))


def find_recordings(source, skipped=None):
    """[(name, path)] of the recordings named by a folder or a list file, in order; names unique.

    The entries of a folder that are not recordings are appended to `skipped` as
    (entry, why), so that the caller can say so (nothing is skipped without a word)."""
    if not os.path.exists(source):
        raise BatchInputError(f"{source}: no such folder or list file (give a folder of recordings or a text file "
                              "with one recording folder per line)")
    paths = []
    if os.path.isdir(source):
        if is_recording(source):
            raise BatchInputError(f"{source} is itself a recording (it holds images/ or rig.yaml); give the folder "
                                  "that holds the recordings, or a list file, or track it with `mcms track`")
        for entry in sorted(os.listdir(source)):
            p = os.path.join(source, entry)
            if os.path.isdir(p) and is_recording(p):
                paths.append(p)
            elif skipped is not None:
                skipped.append((entry, "a folder without images/ or rig.yaml" if os.path.isdir(p) else "not a folder"))
        if not paths:
            raise BatchInputError(f"{source} holds no recording (a sub-folder with images/ or rig.yaml)")
    else:
        base = os.path.dirname(os.path.abspath(source))
        try:
            with open(source, encoding="utf-8-sig") as f:  # a UTF-8 BOM is not part of the first name
                lines = f.read().splitlines()
        except (OSError, UnicodeDecodeError) as e:
            raise BatchInputError(f"list file {source}: cannot be read ({e})") from None
        for line in lines:
            line = line.strip()
            if line and not line.startswith("#"):
                paths.append(line if os.path.isabs(line) else os.path.join(base, line))
        if not paths:
            raise BatchInputError(f"list file {source} names no recording (one folder per line)")
    out, seen = [], set()
    for p in paths:
        name = os.path.basename(os.path.normpath(p)) or "recording"
        unique, k = name, 2
        while unique in seen:
            unique, k = f"{name}_{k}", k + 1
        seen.add(unique)
        out.append((unique, p))
    return out


def started_marker(output):
    return os.path.join(os.path.dirname(output), ".mcms_batch_started")


def track_one(path, output, truth, options):
    """The task run in a worker: mcms.track_recording of one recording, the summary row's numbers."""
    os.makedirs(os.path.dirname(output), exist_ok=True)
    with open(started_marker(output), "w"):  # the task began: a death from here on is this recording's
        pass
    if os.environ.get("MCMS_BATCH_TEST_DIE_ON") == os.path.basename(os.path.normpath(path)):
        os._exit(70)  # the test hook of the module's docstring: a worker that dies
    import mcms

    r = mcms.track_recording(path, output=output, truth=truth, **options)
    e = r["errors"]
    return {
        "frames": r["frames"], "ok": r["ok"], "degraded": r["degraded"], "lost": r["lost"],
        "err_pos_rms_mm": 1e3 * e["position_rms_m"] if e else None,
        "err_rot_rms_deg": e["rotation_rms_rad"] * 57.29577951308232 if e else None,
        "nees": e["mean_nees"] if e else None,
        "nees_consistent": e["nees_consistent"] if e else None,
        "seconds": r["seconds"], "output": r["output"],
    }


def failure_message(exc):
    from distributed import KilledWorker

    if isinstance(exc, KilledWorker):
        return "the worker process died while tracking it (a crash or out of memory; KilledWorker)"
    name = type(exc).__name__
    text = str(exc).strip()
    if name == "InputError":  # mcms.InputError: the message names the file, as the CLI's
        return text
    return f"{name}: {text}" if text else name


def cell(v):
    if v is None:
        return ""
    if isinstance(v, bool):
        return "yes" if v else "no"
    if isinstance(v, float):
        return f"{v:.4g}" if abs(v) < 1e4 else f"{v:.1f}"
    return str(v)


def write_summary(path, rows):
    folder = os.path.dirname(path) or "."
    fd, tmp = tempfile.mkstemp(prefix=".summary.", suffix=".csv.tmp", dir=folder)
    try:
        with os.fdopen(fd, "w", newline="", encoding="utf-8") as f:
            w = csv.writer(f)
            w.writerow(COLUMNS)
            for r in rows:
                w.writerow([cell(r.get(c)) for c in COLUMNS])
        umask = os.umask(0)
        os.umask(umask)
        os.chmod(tmp, 0o666 & ~umask)  # as an ordinary file, not mkstemp's 0600
        os.replace(tmp, path)
    except BaseException:
        if os.path.exists(tmp):
            os.unlink(tmp)
        raise


def print_table(rows, out=sys.stdout):
    shown = ["name", "status", "frames", "ok", "err_pos_rms_mm", "nees", "seconds", "message"]
    cells = [[cell(r.get(c)) for c in shown] for r in rows]
    widths = [max([len(c)] + [min(len(x[i]), 60) for x in cells]) for i, c in enumerate(shown)]
    print("  ".join(c.ljust(w) for c, w in zip(shown, widths)).rstrip(), file=out)
    for x in cells:
        print("  ".join(v.ljust(w) for v, w in zip(x, widths)).rstrip(), file=out)


def parse_args(argv):
    p = argparse.ArgumentParser(
        prog="mcms batch",
        description="Track many recordings on Dask distributed (a local cluster, or --scheduler) and collect their "
                    "results and failures in OUT/summary.csv. A failing recording never stops the others.",
        epilog="Exit status: 0 when at least one recording was tracked (the failed ones are rows with status "
               "'failed' and the message), 3 when every recording failed, 2 on bad input.")
    p.add_argument("source", metavar="DIR_OR_LIST",
                   help="folder whose sub-folders are recordings (images/, rig.yaml, target.yaml, frames.csv), or a "
                        "text file with one recording folder per line")
    p.add_argument("-o", "--output", required=True, metavar="OUT",
                   help="output folder: OUT/summary.csv and OUT/<recording>/poses.csv")
    p.add_argument("--scheduler", metavar="ADDR",
                   help="address of a running Dask scheduler (tcp://host:8786); default: start a local cluster")
    p.add_argument("--workers", type=int, default=2, metavar="N", help="worker processes of the local cluster")
    p.add_argument("--threads-per-worker", type=int, default=1, metavar="N",
                   help="recordings a local worker tracks at once")
    p.add_argument("--threads", type=int, default=1, metavar="N",
                   help="threads of one recording's tracking (reading images, detecting blobs)")
    p.add_argument("--truth", default="auto", metavar="auto|none|PATH",
                   help="truth of each recording for err_pos_rms_mm and nees: auto = <recording>/truth/poses.csv when "
                        "present; PATH relative to each recording folder, or absolute")
    p.add_argument("--rate", type=float, default=0.0,
                   help="frame rate in Hz of recordings without frames.csv (default: not given; such a recording's "
                        "frames are taken 10 Hz apart and its notes say so)")
    p.add_argument("--gain", type=float, help="camera gain in e-/DN (default: measured per recording)")
    p.add_argument("--read-noise", type=float, default=0.0, help="background pixel noise in DN (0 = measured)")
    p.add_argument("--polarity", choices=["bright", "dark"], default="bright")
    p.add_argument("--threshold", type=float, default=0.0, help="detection threshold in DN (0 = automatic)")
    p.add_argument("--connect-timeout", type=float, default=10.0, metavar="S",
                   help="seconds to wait for --scheduler")
    p.add_argument("-q", "--quiet", action="store_true", help="no progress on stderr")
    a = p.parse_args(argv)
    for name in ("workers", "threads_per_worker", "threads"):
        if getattr(a, name) < 1:
            p.error(f"--{name.replace('_', '-')} must be >= 1, got {getattr(a, name)}")
    # The numbers every recording's tracking takes, before the cluster starts (as `mcms track`
    # refuses them): a NaN or a level beyond any image is bad input, not a failed recording.
    import math
    for name, lo, hi, zero_ok in (("rate", 0.0, 1e6, True), ("read_noise", 0.0, 65535.0, True),
                                  ("threshold", 0.0, 65535.0, True), ("gain", 0.0, 1e6, False),
                                  ("connect_timeout", 0.0, 86400.0, False)):
        v = getattr(a, name)
        if v is None:
            continue
        if not (math.isfinite(v) and (lo < v <= hi or (zero_ok and v == 0))):
            p.error(f"--{name.replace('_', '-')} must be a number in {'[' if zero_ok else '('}{lo:g}, {hi:g}], got {v}")
    return a


def truth_for(truth, path):
    if truth == "none":
        return None
    if truth == "auto" or os.path.isabs(truth):
        return truth
    return os.path.join(path, truth)


def refuse_overwriting_inputs(a, recordings):
    """BatchInputError naming both when an output of the batch (OUT/summary.csv, a recording's
    OUT/<name>/poses.csv) is one of its inputs (the list file, a recording's files or truth):
    the check of every mcms command (mcms.require_outputs_spare_inputs), before any work."""
    import mcms

    outputs = [(os.path.join(a.output, "summary.csv"), "batch -o", False)]
    inputs = [a.source] if os.path.isfile(a.source) else []
    for name, path in recordings:
        outputs.append((os.path.join(a.output, name, "poses.csv"), "batch -o", False))
        inputs += [os.path.join(path, f) for f in ("rig.yaml", "target.yaml", "frames.csv", "images")]
        truth = truth_for(a.truth, os.path.abspath(path))
        inputs.append(os.path.join(path, "truth", "poses.csv") if truth == "auto" else truth)
    try:
        mcms.require_outputs_spare_inputs([o for o in outputs], [i for i in inputs if i])
    except mcms.InputError as e:
        raise BatchInputError(str(e)) from None


def refuse_foreign_files(out):
    """BatchInputError when OUT holds anything an earlier batch did not write: a batch replaces
    only its own summary.csv (its column header) and its recordings' folders (each holding
    only the tracker's poses.csv and the task's start marker), never the user's own files
    (what a command may replace, as every mcms command's output folder)."""
    if not os.path.isdir(out):
        return
    def tracker_poses(path):
        try:
            with open(path, encoding="utf-8", errors="replace") as f:
                for line in f:
                    if not line.startswith("#"):
                        return line.startswith("frame,time_s,status,reason,")
        except OSError:
            return False
        return False
    summary = os.path.join(out, "summary.csv")
    ours = False
    if os.path.isfile(summary):
        with open(summary, encoding="utf-8", errors="replace") as f:
            ours = f.readline().rstrip("\r\n") == ",".join(COLUMNS)
    foreign = []
    for entry in sorted(os.listdir(out)):
        p = os.path.join(out, entry)
        if entry == "summary.csv" and ours:
            continue
        if ours and os.path.isdir(p) and not os.path.islink(p):
            files = os.listdir(p)
            if all(f in ("poses.csv", ".mcms_batch_started") for f in files) and \
                    ("poses.csv" not in files or tracker_poses(os.path.join(p, "poses.csv"))):
                continue
            foreign += [os.path.join(entry, f) for f in sorted(files)
                        if f not in ("poses.csv", ".mcms_batch_started") or not tracker_poses(os.path.join(p, f))]
            continue
        foreign.append(entry)
    if foreign:
        shown = ", ".join(foreign[:5]) + (f" and {len(foreign) - 5} more" if len(foreign) > 5 else "")
        raise BatchInputError(f"-o {out} holds files an earlier mcms batch did not write ({shown}); nothing was "
                              "replaced: give a new or empty folder, or move them")


def run(a):
    skipped = []
    recordings = find_recordings(a.source, skipped)
    if skipped:
        print(f"batch: skipped {len(skipped)} {'entry' if len(skipped) == 1 else 'entries'} of {a.source} that "
              "are not recordings: " + ", ".join(f"{e} ({why})" for e, why in skipped), file=sys.stderr)
    if os.path.exists(a.output) and not os.path.isdir(a.output):
        raise BatchInputError(f"-o {a.output} exists and is not a folder; give a folder for the outputs")
    refuse_overwriting_inputs(a, recordings)
    refuse_foreign_files(a.output)
    try:
        import dask
        from distributed import Client, KilledWorker, LocalCluster, wait
    except ImportError as e:
        raise BatchInputError(f"Dask distributed is not installed for {sys.executable} ({e}); on Debian: apt install "
                              "python3-distributed") from None
    # A recording whose worker dies fails at once instead of being retried on the next
    # worker (which it might kill too). This applies to the local cluster's scheduler; a
    # scheduler given with --scheduler has its own (Dask's default: 3 retries).
    dask.config.set({"distributed.scheduler.allowed-failures": 0})
    options = {"frame_rate_hz": a.rate, "read_noise_dn": a.read_noise, "polarity": a.polarity,
               "threshold_dn": a.threshold, "threads": a.threads}
    if a.gain is not None:
        options["gain_e_per_dn"] = a.gain
    cluster = None
    if a.scheduler:
        try:
            client = Client(a.scheduler, timeout=f"{a.connect_timeout}s")
        except Exception as e:  # OSError, TimeoutError, ValueError on a malformed address
            raise BatchInputError(f"--scheduler {a.scheduler}: cannot connect to a Dask scheduler there "
                                  f"({type(e).__name__}: {e})") from None
        try:
            client.wait_for_workers(1, timeout=a.connect_timeout)
        except Exception:
            client.close()
            raise BatchInputError(f"--scheduler {a.scheduler}: the scheduler has no worker (none joined within "
                                  f"{a.connect_timeout:g} s); start workers with `dask worker {a.scheduler}`") from None
        where = f"scheduler {a.scheduler}"
    else:
        cluster = LocalCluster(n_workers=a.workers, threads_per_worker=a.threads_per_worker, processes=True,
                               dashboard_address=None, silence_logs=logging.CRITICAL)
        client = Client(cluster)
        where = f"a local cluster of {a.workers} workers x {a.threads_per_worker} threads"
    logging.getLogger("distributed").setLevel(logging.CRITICAL)
    try:
        os.makedirs(a.output, exist_ok=True)
        if not os.access(a.output, os.W_OK):
            raise OSError("not writable")
    except OSError as e:
        client.close()
        if cluster is not None:
            cluster.close()
        raise BatchInputError(f"-o {a.output}: cannot write there ({e})") from None
    start = time.perf_counter()
    rows = {}
    try:
        if not a.quiet:
            print(f"batch: {len(recordings)} recordings on {where}", file=sys.stderr, flush=True)
        # Recordings are handed out no faster than the workers' threads take them: a worker
        # never holds a queued recording, so a worker that dies takes only the recording it
        # was tracking with it (Dask would otherwise fail every task assigned to it).
        pending = list(enumerate(recordings))
        inflight = {}
        attempts = {}
        done = 0

        def free_threads():
            return max(1, sum(client.nthreads().values())) - len(inflight)

        while pending or inflight:
            while pending and free_threads() > 0:
                i, (name, path) = pending.pop(0)
                out = os.path.abspath(os.path.join(a.output, name, "poses.csv"))
                if os.path.exists(started_marker(out)):
                    os.unlink(started_marker(out))
                attempts[name] = attempts.get(name, 0) + 1
                f = client.submit(track_one, os.path.abspath(path), out, truth_for(a.truth, os.path.abspath(path)),
                                  options, key=f"mcms-track-{i}-{name}-{attempts[name]}", pure=False, retries=0)
                inflight[f] = (i, name, path, out)
            try:
                # Also wakes up now and then: a restarted worker takes the next recording.
                wait(list(inflight), timeout=1.0, return_when="FIRST_COMPLETED")
            except TimeoutError:
                pass
            for f in [f for f in inflight if f.done()]:
                i, name, path, out = inflight.pop(f)
                try:
                    row = {"status": "ok", **f.result()}
                except KilledWorker as e:
                    # A task that Dask had handed to a worker which then died of something
                    # else (another recording) never began: it goes back in the queue.
                    if not os.path.exists(started_marker(out)) and attempts[name] < 3:
                        f.release()
                        pending.insert(0, (i, (name, path)))
                        continue
                    row = {"status": "failed", "message": failure_message(e)}
                except Exception as e:  # the recording's error
                    row = {"status": "failed", "message": failure_message(e)}
                f.release()
                if os.path.exists(started_marker(out)):
                    os.unlink(started_marker(out))
                    if not os.listdir(os.path.dirname(out)):
                        os.rmdir(os.path.dirname(out))
                row["name"] = name
                rows[name] = row
                done += 1
                if not a.quiet:
                    what = (f"ok, {row['ok']}/{row['frames']} frames ok, {row['seconds']:.1f} s"
                            if row["status"] == "ok" else "FAILED: " + row["message"])
                    print(f"batch: {done}/{len(recordings)} {name}: {what}", file=sys.stderr, flush=True)
    finally:
        client.close()
        if cluster is not None:
            cluster.close()
    table = [rows[name] for name, _ in recordings]
    write_summary(os.path.join(a.output, "summary.csv"), table)
    print_table(table)
    failed = sum(r["status"] != "ok" for r in table)
    print(f"{len(table) - failed} of {len(table)} recordings tracked, {failed} failed, in "
          f"{time.perf_counter() - start:.1f} s -> {os.path.join(a.output, 'summary.csv')}")
    return 3 if failed == len(table) else 0


def main(argv=None):
    a = parse_args(sys.argv[1:] if argv is None else argv)
    try:
        return run(a)
    except BatchInputError as e:
        print(f"mcms batch: error: {e}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
