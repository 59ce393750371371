"""Many recordings: mcms.track_recording / mcms.evaluate_poses, and `mcms batch` (python/mcms_batch.py)
on Dask distributed local clusters: results and per-recording failures in one table, a failing
recording or a dying worker never stops the others."""
import csv
import os
import shutil
import subprocess
import tempfile
import unittest

import mcms

try:
    import distributed
except ImportError:  # pragma: no cover
    distributed = None

FRAMES = 3


def read_summary(path):
    with open(path, newline="") as f:
        return {r["name"]: r for r in csv.DictReader(f)}


class Batch(unittest.TestCase):
    @classmethod
    def setUpClass(cls):
        cls.cli = os.environ.get("MCMS_CLI")
        if not cls.cli:
            raise unittest.SkipTest("skipped: the mcms CLI is not built (MCMS_CLI unset)")
        cls.tmp = tempfile.TemporaryDirectory()
        cls.root = os.path.join(cls.tmp.name, "recordings")
        os.makedirs(cls.root)
        # Two small renders (different seeds), a third recording copied from the first, and
        # copies made bad in two ways.
        for name, seed in (("rec_a", 1), ("rec_b", 2)):
            subprocess.run([cls.cli, "render", "-q", "--frames", str(FRAMES), "--seed", str(seed), "--threads", "2",
                            "-o", os.path.join(cls.root, name)], check=True)
        shutil.copytree(os.path.join(cls.root, "rec_a"), os.path.join(cls.root, "rec_c"))
        broken = os.path.join(cls.root, "rec_broken_rig")
        shutil.copytree(os.path.join(cls.root, "rec_a"), broken)
        with open(os.path.join(broken, "rig.yaml"), "w") as f:
            f.write("cameras: [ {name: cam0, lensmodel: \n")
        # First in order: Dask may already have handed the next recording to its worker.
        shutil.copytree(os.path.join(cls.root, "rec_b"), os.path.join(cls.root, "rec_0_dies"))
        os.makedirs(os.path.join(cls.root, "not_a_recording"))  # skipped: no images/, no rig.yaml
        with open(os.path.join(cls.root, "notes.txt"), "w") as f:  # skipped: a stray file
            f.write("not a recording\n")

    @classmethod
    def tearDownClass(cls):
        cls.tmp.cleanup()

    def batch(self, *args, env=None, timeout=120):
        e = dict(os.environ)
        e.update(env or {})
        return subprocess.run([self.cli, "batch", *args], capture_output=True, text=True, env=e, timeout=timeout)

    def check_good(self, row):
        self.assertEqual(row["status"], "ok", row)
        self.assertEqual(int(row["frames"]), FRAMES)
        self.assertGreaterEqual(int(row["ok"]), FRAMES - 1)
        # Rendered recordings with their truth: sub-millimetre error, a finite NEES.
        self.assertLess(float(row["err_pos_rms_mm"]), 1.0)
        self.assertTrue(0 < float(row["nees"]) < 100, row)
        self.assertTrue(os.path.isfile(row["output"]))
        self.assertEqual(row["message"], "")

    def test_track_recording_and_evaluate_poses(self):
        with tempfile.TemporaryDirectory() as d:
            out = os.path.join(d, "poses.csv")
            r = mcms.track_recording(os.path.join(self.root, "rec_a"), output=out, truth="auto", threads=2)
            self.assertEqual(r["output"], out)
            self.assertEqual(r["frames"], FRAMES)
            self.assertEqual(r["ok"] + r["degraded"] + r["lost"], FRAMES)
            e = r["errors"]
            self.assertTrue(r["truth"].endswith(os.path.join("truth", "poses.csv")))
            self.assertLess(e["position_rms_m"], 1e-3)
            self.assertEqual(len(e["nees_band"]), 2)
            self.assertTrue(any(line.startswith("truth: mean NEES") for line in r["notes"]))
            # The same errors from the CSV written.
            again = mcms.evaluate_poses(out, r["truth"])
            self.assertEqual(again["evaluated"], e["evaluated"])
            self.assertAlmostEqual(again["position_rms_m"], e["position_rms_m"], delta=1e-9)
            self.assertAlmostEqual(again["mean_nees"], e["mean_nees"], delta=1e-6 * e["mean_nees"])
            # Without a truth: no errors.
            self.assertIsNone(mcms.track_recording(os.path.join(self.root, "rec_a"), output=out)["errors"])
            # A truth that lacks frames of the recording is refused, naming it and the frame.
            short = os.path.join(d, "short_truth.csv")
            with open(r["truth"]) as f, open(short, "w") as g:
                g.writelines(f.readlines()[:2])
            with self.assertRaisesRegex(mcms.InputError, "short_truth.csv has no row for frame 1"):
                mcms.evaluate_poses(out, short)
            with self.assertRaisesRegex(mcms.InputError, "short_truth.csv has no row for frame 1"):
                mcms.track_recording(os.path.join(self.root, "rec_a"), output=os.path.join(d, "y.csv"), truth=short)
            self.assertFalse(os.path.exists(os.path.join(d, "y.csv")))
        with self.assertRaisesRegex(mcms.InputError, r"rec_broken_rig.*rig\.yaml"):
            mcms.track_recording(os.path.join(self.root, "rec_broken_rig"), output=os.path.join(d, "x.csv"))
        with self.assertRaisesRegex(mcms.InputError, "/no/such/recording.*does not exist"):
            mcms.track_recording("/no/such/recording")
        with self.assertRaisesRegex(mcms.InputError, "'results'"):
            mcms.evaluate_poses(42, os.path.join(self.root, "rec_a", "truth", "poses.csv"))

    @unittest.skipIf(distributed is None, "skipped: python3-distributed not installed")
    def test_local_cluster_failures_do_not_stop_the_others(self):
        with tempfile.TemporaryDirectory() as d:
            out = os.path.join(d, "out")
            r = self.batch(self.root, "-o", out, "--workers", "2", env={"MCMS_BATCH_TEST_DIE_ON": "rec_0_dies"})
            self.assertEqual(r.returncode, 0, r.stderr)
            rows = read_summary(os.path.join(out, "summary.csv"))
            self.assertEqual(list(rows), ["rec_0_dies", "rec_a", "rec_b", "rec_broken_rig", "rec_c"])
            for name in ("rec_a", "rec_b", "rec_c"):
                self.check_good(rows[name])
                self.assertEqual(rows[name]["output"], os.path.join(out, name, "poses.csv"))
            self.assertEqual(rows["rec_broken_rig"]["status"], "failed")
            self.assertIn(os.path.join("rec_broken_rig", "rig.yaml"), rows["rec_broken_rig"]["message"])
            self.assertEqual(rows["rec_0_dies"]["status"], "failed")
            self.assertIn("worker process died", rows["rec_0_dies"]["message"])
            self.assertFalse(os.path.exists(os.path.join(out, "rec_broken_rig")))
            self.assertFalse(os.path.exists(os.path.join(out, "rec_0_dies")))
            self.assertEqual(sorted(os.listdir(os.path.join(out, "rec_a"))), ["poses.csv"])
            # The table on stdout, progress on stderr.
            self.assertIn("3 of 5 recordings tracked, 2 failed", r.stdout)
            self.assertIn("rec_0_dies: FAILED", r.stderr)
            # Issue 29: what is not a recording is skipped with a word, not silently.
            self.assertIn("skipped 2 entries", r.stderr)
            self.assertIn("not_a_recording (a folder without images/ or rig.yaml)", r.stderr)
            self.assertIn("notes.txt (not a folder)", r.stderr)
            # The same recording tracked alone gives the same figures (the cluster changes nothing).
            alone = mcms.track_recording(os.path.join(self.root, "rec_c"), output=os.path.join(d, "c.csv"),
                                         truth="auto")
            self.assertAlmostEqual(float(rows["rec_c"]["err_pos_rms_mm"]), 1e3 * alone["errors"]["position_rms_m"],
                                   delta=1e-3 * float(rows["rec_c"]["err_pos_rms_mm"]))

    @unittest.skipIf(distributed is None, "skipped: python3-distributed not installed")
    def test_scheduler_address_and_list_file(self):
        import logging

        from distributed import LocalCluster

        with tempfile.TemporaryDirectory() as d, \
                LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None,
                             silence_logs=logging.CRITICAL) as cluster:
            listing = os.path.join(d, "list.txt")
            with open(listing, "w") as f:
                f.write("# two recordings, one missing\n")
                f.write(os.path.join(self.root, "rec_a") + "\n\n")
                f.write(os.path.relpath(os.path.join(self.root, "rec_c"), d) + "\n")
                f.write(os.path.join(d, "gone") + "\n")
            out = os.path.join(d, "out")
            r = self.batch(listing, "-o", out, "--scheduler", cluster.scheduler_address, "--truth", "none")
            self.assertEqual(r.returncode, 0, r.stderr)
            self.assertIn("scheduler " + cluster.scheduler_address, r.stderr)
            rows = read_summary(os.path.join(out, "summary.csv"))
            self.assertEqual(list(rows), ["rec_a", "rec_c", "gone"])
            for name in ("rec_a", "rec_c"):
                self.assertEqual(rows[name]["status"], "ok")
                self.assertEqual(rows[name]["err_pos_rms_mm"], "")  # --truth none
            self.assertEqual(rows["gone"]["status"], "failed")
            self.assertIn(os.path.join(d, "gone") + ": does not exist", rows["gone"]["message"])

    def test_list_file_with_a_utf8_bom(self):
        # Issue 29: the BOM became part of the first folder's name.
        import mcms_batch

        with tempfile.TemporaryDirectory() as d:
            listing = os.path.join(d, "list.txt")
            with open(listing, "w", encoding="utf-8-sig") as f:
                f.write(os.path.join(self.root, "rec_a") + "\n" + os.path.join(self.root, "rec_b") + "\n")
            with open(listing, "rb") as f:
                self.assertEqual(f.read(3), b"\xef\xbb\xbf")
            found = mcms_batch.find_recordings(listing)
            self.assertEqual(found, [("rec_a", os.path.join(self.root, "rec_a")),
                                     ("rec_b", os.path.join(self.root, "rec_b"))])

    def test_an_output_that_is_an_input_is_refused(self):
        # Issue 28: the same file by device and inode (directly, another spelling, a symlink).
        rec = os.path.join(self.root, "rec_a")
        frames = os.path.join(rec, "frames.csv")
        with open(frames, "rb") as f:
            before = f.read()
        with tempfile.TemporaryDirectory() as d:
            link = os.path.join(d, "alias.csv")
            os.symlink(frames, link)
            for spelling in (frames, os.path.join(rec, "images", "..", "frames.csv"), link):
                with self.assertRaisesRegex(mcms.InputError, r"is the input .*frames\.csv"):
                    mcms.track_recording(rec, output=spelling)
                with open(frames, "rb") as f:
                    self.assertEqual(f.read(), before)
                self.assertTrue(os.path.islink(link))
            with self.assertRaisesRegex(mcms.InputError, "x -o .*holds the input"):
                mcms.require_outputs_spare_inputs([(rec, "x -o", True)], [frames])
            mcms.require_outputs_spare_inputs([(os.path.join(d, "new.csv"), "x -o", False)], [frames, "/no/such/file"])
            # Issue 37: a rig of camera model files; the models are inputs read through the rig.
            rigm = os.path.join(d, "rigm.yaml")
            with open(rigm, "w") as f:
                f.write("cameras:\n" + "".join(
                    f"  - {{name: cam{c}, model: {os.path.join(rec, 'cameras', f'cam{c}.cameramodel')}}}\n"
                    for c in range(4)))
            model = os.path.join(rec, "cameras", "cam0.cameramodel")
            with open(model, "rb") as f:
                model_before = f.read()
            with self.assertRaisesRegex(mcms.InputError, "reads through another of its inputs"):
                mcms.track_recording(rec, rig=rigm, output=model)
            with open(model, "rb") as f:
                self.assertEqual(f.read(), model_before)

    @unittest.skipIf(distributed is None, "skipped: python3-distributed not installed")
    def test_batch_output_that_is_an_input_is_refused(self):
        with tempfile.TemporaryDirectory() as d:
            # Each recording's truth named poses.csv beside it, and -o the recordings' folder:
            # OUT/<name>/poses.csv would overwrite the truth.
            recs = os.path.join(d, "recs")
            shutil.copytree(os.path.join(self.root, "rec_a"), os.path.join(recs, "rec_a"))
            truth = os.path.join(recs, "rec_a", "poses.csv")
            shutil.copy(os.path.join(recs, "rec_a", "truth", "poses.csv"), truth)
            with open(truth, "rb") as f:
                before = f.read()
            r = self.batch(recs, "-o", recs, "--truth", "poses.csv")
            self.assertEqual(r.returncode, 2, r.stderr)
            self.assertIn("is the input " + truth, r.stderr)
            with open(truth, "rb") as f:
                self.assertEqual(f.read(), before)
            self.assertFalse(os.path.exists(os.path.join(recs, "summary.csv")))
            # A list file named summary.csv in the output folder.
            out = os.path.join(d, "out")
            os.makedirs(out)
            listing = os.path.join(out, "summary.csv")
            with open(listing, "w") as f:
                f.write(os.path.join(recs, "rec_a") + "\n")
            r = self.batch(listing, "-o", out)
            self.assertEqual(r.returncode, 2, r.stderr)
            self.assertIn("is the input " + listing, r.stderr)
            with open(listing) as f:
                self.assertEqual(f.read(), os.path.join(recs, "rec_a") + "\n")
            # Issue 37: the output inside a recording's images (a folder the run reads whole).
            inside = os.path.join(recs, "rec_a", "images")
            r = self.batch(recs, "-o", inside)
            self.assertEqual(r.returncode, 2, r.stderr)
            self.assertIn("lies inside the input folder", r.stderr)
            self.assertEqual(sorted(os.listdir(inside)), ["cam0", "cam1", "cam2", "cam3"])

    @unittest.skipIf(distributed is None, "skipped: python3-distributed not installed")
    def test_bad_input(self):
        with tempfile.TemporaryDirectory() as d:
            cases = [
                ([os.path.join(d, "missing"), "-o", os.path.join(d, "o")], "missing: no such folder or list file"),
                ([d, "-o", os.path.join(d, "o")], "holds no recording"),
                ([os.path.join(self.root, "rec_a"), "-o", os.path.join(d, "o")], "is itself a recording"),
                ([self.root, "-o", os.path.join(self.root, "rec_a", "rig.yaml")], "is not a folder"),
                ([self.root, "-o", os.path.join(d, "o"), "--scheduler", "tcp://127.0.0.1:9", "--connect-timeout", "2"],
                 "--scheduler tcp://127.0.0.1:9: cannot connect"),
            ]
            cases.append(([self.root, "-o", os.path.join(d, "o"), "--rate", "nan"], "--rate must be a number in"))
            cases.append(([self.root, "-o", os.path.join(d, "o"), "--read-noise", "1e300"], "--read-noise must be"))
            for args, needle in cases:
                r = self.batch(*args)
                self.assertEqual(r.returncode, 2, (args, r.stderr))
                self.assertIn(needle, r.stderr)
                self.assertFalse(os.path.exists(os.path.join(d, "o", "summary.csv")))
            # Every recording failing: exit 3, the table still written.
            listing = os.path.join(d, "bad.txt")
            with open(listing, "w") as f:
                f.write(os.path.join(self.root, "rec_broken_rig") + "\n")
            r = self.batch(listing, "-o", os.path.join(d, "o3"), "--workers", "1")
            self.assertEqual(r.returncode, 3, r.stderr)
            rows = read_summary(os.path.join(d, "o3", "summary.csv"))
            self.assertEqual(rows["rec_broken_rig"]["status"], "failed")
            # An earlier batch's output is replaced (the same run again)...
            r = self.batch(listing, "-o", os.path.join(d, "o3"), "--workers", "1")
            self.assertEqual(r.returncode, 3, r.stderr)
            # ... a folder holding the user's own summary.csv and a recording's poses.csv is
            # refused before any work, both kept (issue 53).
            mine = os.path.join(d, "mine")
            os.makedirs(os.path.join(mine, "rec_a"))
            for name, text in (("summary.csv", "my own summary\n"), (os.path.join("rec_a", "poses.csv"), "my notes\n")):
                with open(os.path.join(mine, name), "w") as f:
                    f.write(text)
            r = self.batch(listing, "-o", mine, "--workers", "1")
            self.assertEqual(r.returncode, 2, r.stderr)
            self.assertIn("holds files an earlier mcms batch did not write (rec_a, summary.csv)", r.stderr)
            with open(os.path.join(mine, "summary.csv")) as f:
                self.assertEqual(f.read(), "my own summary\n")
            with open(os.path.join(mine, "rec_a", "poses.csv")) as f:
                self.assertEqual(f.read(), "my notes\n")


if __name__ == "__main__":
    unittest.main()
